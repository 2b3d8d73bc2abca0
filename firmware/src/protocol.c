#include "protocol.h"

#include <string.h>

#include "cobs.h"
#include "crc16.h"

static proto_writer put;
static uint8_t mode = PROTO_MODE_POLLED;
static uint8_t seq;

#define PKT_MAX (PROTO_RECORD_PACKET_LEN > MOTIONCAL_PACKET_LEN ? PROTO_RECORD_PACKET_LEN \
                                                                : MOTIONCAL_PACKET_LEN)
static uint8_t pkt[PKT_MAX]; /* the longest packet */
static uint8_t command;
static uint8_t pkt_len;                   /* 0: not inside a packet */
static uint8_t pkt_need;                  /* length of the packet being received */
static uint8_t pkt_second;                /* its second byte */
static uint16_t pkt_start_ms;
static struct motioncal cal;
static struct still_settings pose_settings = {
    STILL_DEFAULT_PERIOD_MS,       STILL_DEFAULT_WINDOW,         STILL_DEFAULT_HOLD_WINDOWS,
    STILL_DEFAULT_HOLDOFF_MS,      STILL_DEFAULT_ACCEL_THRESHOLD, STILL_DEFAULT_GYRO_THRESHOLD,
    STILL_DEFAULT_BEEP_MS};

static void put_nothing(uint8_t byte) { (void)byte; }

void proto_set_writer(proto_writer writer) { put = writer ? writer : put_nothing; }

uint8_t proto_mode(void) { return mode; }

const struct motioncal *proto_cal(void) { return &cal; }

const struct still_settings *proto_pose_settings(void) { return &pose_settings; }

const uint8_t *proto_record_packet(void) { return pkt + 2; }

uint8_t proto_command(void) { return command; }

void proto_put_str(const char *s)
{
    while (*s) put((uint8_t)*s++);
}

void proto_put_int(int32_t v)
{
    char digits[11];
    uint8_t n = 0;
    uint32_t u;
    if (v < 0) {
        put('-');
        u = (uint32_t)(-(v + 1)) + 1u;
    } else {
        u = (uint32_t)v;
    }
    do {
        digits[n++] = (char)('0' + u % 10u);
        u /= 10u;
    } while (u);
    while (n) put((uint8_t)digits[--n]);
}

void proto_put_fixed4(float x)
{
    /* round half away from zero to 1e-4, like printf("%.4f") for these magnitudes */
    uint8_t neg = x < 0.0f;
    float a = neg ? -x : x;
    if (a > 200000.0f) a = 200000.0f; /* keep within int32 after scaling */
    uint32_t scaled = (uint32_t)(a * 10000.0f + 0.5f);
    uint32_t whole = scaled / 10000u;
    uint16_t frac = (uint16_t)(scaled % 10000u);
    if (neg && scaled) put('-');
    proto_put_int((int32_t)whole);
    put('.');
    put((uint8_t)('0' + frac / 1000u));
    put((uint8_t)('0' + frac / 100u % 10u));
    put((uint8_t)('0' + frac / 10u % 10u));
    put((uint8_t)('0' + frac % 10u));
}

void proto_send_binary(const int16_t *values, uint8_t k)
{
    for (uint8_t i = 0; i < k; i++) {
        uint16_t u = (uint16_t)values[i];
        put((uint8_t)(u & 0xFF));
        put((uint8_t)(u >> 8));
    }
    put('\n');
}

/* COBS(seq, head, body, CRC-16/CCITT-FALSE LE) + 0x00; hn + bn <= PROTO_FRAME_MAX bytes (the
 * longest: a 'K' frame, 3 + TC_STORE_BYTES). Head and body are separate so that a record is
 * sent from where it lies, without a copy on the stack. */
#define PROTO_FRAME_MAX (3 + TC_STORE_BYTES)
static void send_frame2(const uint8_t *head, uint8_t hn, const uint8_t *body, uint8_t bn)
{
    uint8_t raw[1 + PROTO_FRAME_MAX + 2];
    uint8_t m = 0, i;
    raw[m++] = seq++;
    for (i = 0; i < hn; i++) raw[m++] = head[i];
    for (i = 0; i < bn; i++) raw[m++] = body[i];
    uint16_t crc = crc16_ccitt(raw, m);
    raw[m++] = (uint8_t)(crc & 0xFF);
    raw[m++] = (uint8_t)(crc >> 8);
    cobs_write(raw, m, put);
    put(0);
}

static void send_frame(const uint8_t *payload, uint8_t n) { send_frame2(payload, n, 0, 0); }

static uint8_t put_le(uint8_t *p, uint32_t v, uint8_t bytes)
{
    for (uint8_t i = 0; i < bytes; i++) {
        p[i] = (uint8_t)(v & 0xFF);
        v >>= 8;
    }
    return bytes;
}

void proto_send_framed(const int16_t *values, uint8_t k)
{
    uint8_t payload[2 * PROTO_MAX_CHANNELS];
    if (k > PROTO_MAX_CHANNELS) k = PROTO_MAX_CHANNELS;
    uint8_t n = 0;
    for (uint8_t i = 0; i < k; i++) n += put_le(payload + n, (uint16_t)values[i], 2);
    send_frame(payload, n);
}

void proto_send_pose(const struct still_pose *pose, uint8_t k)
{
    uint8_t payload[PROTO_FRAME_MAX];
    if (k > STILL_CHANNELS) k = STILL_CHANNELS;
    uint8_t n = 0;
    payload[n++] = PROTO_FRAME_POSE;
    n += put_le(payload + n, pose->index, 2);
    n += put_le(payload + n, pose->n, 2);
    for (uint8_t i = 0; i < k; i++) n += put_le(payload + n, (uint32_t)pose->sum[i], 4);
    send_frame(payload, n);
}

void proto_send_status(const struct still_status *st)
{
    uint8_t payload[17];
    uint8_t n = 0;
    payload[n++] = PROTO_FRAME_STATUS;
    payload[n++] = st->flags;
    payload[n++] = st->run;
    n += put_le(payload + n, st->poses, 2);
    for (uint8_t i = 0; i < 3; i++) n += put_le(payload + n, (uint16_t)st->accel[i], 2);
    for (uint8_t i = 0; i < 3; i++) n += put_le(payload + n, (uint16_t)st->rate[i], 2);
    send_frame(payload, n);
}

void proto_send_settings(uint8_t accepted, const struct still_settings *s)
{
    uint8_t payload[3 + STILL_SETTINGS_BYTES];
    payload[0] = PROTO_FRAME_SETTINGS;
    payload[1] = accepted;
    payload[2] = STILL_SETTINGS_VERSION;
    still_pack(s, payload + 3);
    send_frame(payload, sizeof payload);
}

void proto_send_record(uint8_t status, uint8_t flags, const uint8_t record[TC_STORE_BYTES])
{
    const uint8_t head[3] = {PROTO_FRAME_RECORD, status, flags};
    send_frame2(head, sizeof head, record, TC_STORE_BYTES);
}

static uint8_t put_f32(uint8_t *p, float v)
{
    uint32_t u;
    memcpy(&u, &v, sizeof u); /* IEEE binary32 */
    return put_le(p, u, 4);
}

void proto_send_quality(const struct proto_quality *q)
{
    uint8_t payload[39];
    uint8_t n = 0, i;
    payload[n++] = PROTO_FRAME_QUALITY;
    payload[n++] = 1; /* version of the frame */
    payload[n++] = (uint8_t)q->code;
    payload[n++] = (uint8_t)q->descent_code;
    n += put_le(payload + n, q->warnings, 2);
    n += put_le(payload + n, q->n, 2);
    payload[n++] = q->iterations;
    n += put_le(payload + n, q->descent_iterations, 2);
    for (i = 0; i < 3; i++) n += put_f32(payload + n, q->center[i]);
    n += put_f32(payload + n, q->rms);
    n += put_f32(payload + n, q->spread);
    for (i = 0; i < 6; i++) payload[n++] = q->faces[i];
    n += put_le(payload + n, q->stack_free, 2);
    send_frame(payload, n);
}

void proto_send_text(const int16_t *values, uint8_t k)
{
    for (uint8_t i = 0; i < k; i++) {
        if (i) put(',');
        proto_put_int(values[i]);
    }
    put('\r');
    put('\n');
}

void proto_send_raw_mpu(const int16_t *mpu)
{
    proto_put_str("Raw:");
    for (uint8_t i = 0; i < 9; i++) {
        int32_t v = 0;
        if (i < 3) {
            v = mpu[i] / 2; /* 16384 -> 8192 counts per g */
        } else if (i < 6) {
            v = (int32_t)mpu[i] * 16 / 131; /* 131 -> 16 counts per deg/s */
        }
        if (i) put(',');
        proto_put_int(v);
    }
    put('\r');
    put('\n');
}

void proto_send_stream(const int16_t *values, uint8_t k)
{
    switch (mode) {
    case PROTO_MODE_BINARY: proto_send_binary(values, k); break;
    case PROTO_MODE_FRAMED: proto_send_framed(values, k); break;
    case PROTO_MODE_TEXT: proto_send_text(values, k); break;
    case PROTO_MODE_RAW: proto_send_raw_mpu(values); break;
    default: break; /* polled; the still-pose mode sends poses, not samples */
    }
}

static float get_f32(const uint8_t *p)
{
    float f;
    memcpy(&f, p, sizeof f); /* AVR and ARM are little-endian, float is IEEE binary32 */
    return f;
}

void proto_send_cal_lines(const struct motioncal *c)
{
    proto_put_str("Cal1:");
    const float one[10] = {c->accel[0], c->accel[1], c->accel[2], c->gyro[0], c->gyro[1],
                           c->gyro[2],  c->mag[0],   c->mag[1],   c->mag[2],  c->field};
    for (uint8_t i = 0; i < 10; i++) {
        if (i) put(',');
        proto_put_fixed4(one[i]);
    }
    proto_put_str("\r\nCal2:");
    /* soft iron xx yy zz xy xz yz -> 3x3 row-major */
    const float *s = c->soft;
    const float two[9] = {s[0], s[3], s[4], s[3], s[1], s[5], s[4], s[5], s[2]};
    for (uint8_t i = 0; i < 9; i++) {
        if (i) put(',');
        proto_put_fixed4(two[i]);
    }
    proto_put_str("\r\n");
}

static enum proto_event settings_done(void)
{
    uint16_t crc = crc16_ccitt(pkt, PROTO_SETTINGS_PACKET_LEN - 2);
    uint16_t got = (uint16_t)pkt[PROTO_SETTINGS_PACKET_LEN - 2] |
                   (uint16_t)((uint16_t)pkt[PROTO_SETTINGS_PACKET_LEN - 1] << 8);
    pkt_len = 0;
    if (crc != got) return PROTO_EV_NONE; /* damaged: no answer, as for MotionCal's packet */
    struct still_settings s;
    still_unpack(pkt + 2, &s);
    if (!still_valid(&s)) {
        proto_send_settings(0, &pose_settings); /* refused: the settings in use */
        return PROTO_EV_NONE;
    }
    pose_settings = s;
    proto_send_settings(1, &pose_settings);
    return PROTO_EV_SETTINGS;
}

static enum proto_event packet_done(void)
{
    uint16_t crc = crc16_modbus(pkt, MOTIONCAL_PACKET_LEN - 2);
    uint16_t got = (uint16_t)pkt[MOTIONCAL_PACKET_LEN - 2] |
                   (uint16_t)((uint16_t)pkt[MOTIONCAL_PACKET_LEN - 1] << 8);
    pkt_len = 0;
    if (crc != got) return PROTO_EV_NONE;
    float f[16];
    for (uint8_t i = 0; i < 16; i++) f[i] = get_f32(pkt + 2 + 4 * i);
    memcpy(cal.accel, f, sizeof cal.accel);
    memcpy(cal.gyro, f + 3, sizeof cal.gyro);
    memcpy(cal.mag, f + 6, sizeof cal.mag);
    cal.field = f[9];
    memcpy(cal.soft, f + 10, sizeof cal.soft);
    proto_send_cal_lines(&cal);
    return PROTO_EV_CAL;
}

static enum proto_event packet_start(uint8_t byte, uint8_t need, uint8_t second,
                                     uint16_t now_ms)
{
    pkt[0] = byte;
    pkt_len = 1;
    pkt_need = need;
    pkt_second = second;
    pkt_start_ms = now_ms;
    return PROTO_EV_NONE;
}

enum proto_event proto_feed(uint8_t byte, uint16_t now_ms)
{
    if (!put) put = put_nothing;
    if (pkt_len && (uint16_t)(now_ms - pkt_start_ms) > MOTIONCAL_TIMEOUT_MS) {
        pkt_len = 0; /* a packet cut short: treat this byte afresh */
    }
    if (pkt_len == 1) {
        if (byte == pkt_second) {
            pkt[pkt_len++] = byte;
            return PROTO_EV_NONE;
        }
        pkt_len = 0; /* the first byte alone was not a packet start */
    } else if (pkt_len) {
        pkt[pkt_len++] = byte;
        if (pkt_len < pkt_need) return PROTO_EV_NONE;
        if (pkt[0] == PROTO_RECORD_START) {
            pkt_len = 0;
            return PROTO_EV_RECORD; /* its CRC is the record's own: board_cal checks it */
        }
        return pkt[0] == PROTO_SETTINGS_START ? settings_done() : packet_done();
    }
    switch (byte) {
    case 117:
        return packet_start(byte, MOTIONCAL_PACKET_LEN, 84, now_ms);
    case PROTO_SETTINGS_START:
        return packet_start(byte, PROTO_SETTINGS_PACKET_LEN, PROTO_SETTINGS_VERSION, now_ms);
    case PROTO_RECORD_START:
        return packet_start(byte, PROTO_RECORD_PACKET_LEN, PROTO_RECORD_VERSION, now_ms);
    case PROTO_CAL_COMPUTE:
    case PROTO_CAL_REPORT:
    case PROTO_CAL_APPLY:
    case PROTO_CAL_RAW:
#if SIMULATED
    case PROTO_CAL_DAMAGE:
#endif
        command = byte;
        return PROTO_EV_COMMAND;
    case PROTO_REQUEST:
        return PROTO_EV_REQUEST;
    case PROTO_MODE_POLLED:
    case PROTO_MODE_BINARY:
    case PROTO_MODE_FRAMED:
    case PROTO_MODE_TEXT:
    case PROTO_MODE_RAW:
    case PROTO_MODE_POSES:
        mode = byte;
        return PROTO_EV_MODE;
    default:
        return PROTO_EV_NONE;
    }
}
