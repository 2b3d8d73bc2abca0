// calibrate_mpu6050: the board calibrates its MPU-6050 accelerometer itself, the sphere-centre method's
// program (sensors_calibrate_program) with the triaxcal library.
//
// Hold the board still in a pose until it beeps (and prints the pose), turn it to the next,
// and so on: the sphere-centre method's globe is 7 latitudes x 12 turns about the vertical, 84 poses. After the
// 84th (or when you send 'c') the board fits the offsets (the centre of the sphere) and the
// three gains, prints them with their quality, stores them in the EEPROM (a record with
// version and CRC) and then prints calibrated readings, in g, once a second. At start-up a
// stored calibration is read back and used. Send 'r' for raw readings, 'a' for calibrated.
// The sphere-centre method's own centre search (tc_descend_center, 26 neighbours, variable step) is in the
// library too; the project firmware runs both (firmware/src/board_cal.c); on an Uno beside
// Wire and Serial the flash holds one of them.
//
// Wiring: MPU-6050 SDA -> A4, SCL -> A5, VCC, GND, AD0 low; a buzzer on D8 (optional).
// Serial: 115200 baud. The MPU-6050 at +-2 g: 16384 counts per g.
#include <EEPROM.h>
#include <Wire.h>
#include <triaxcal.h>

static const uint8_t MPU = 0x68;
static const uint8_t BUZZER_PIN = 8;
static const uint16_t GLOBE_POSES = 84;   // fit after this many poses
static const float COUNTS_PER_G = 16384;  // the radius: calibrated counts per g
static const int EEPROM_AT = 0;           // where the record lives

TC_POSES_STORAGE(store, 48);  // 48 poses kept (12 bytes of RAM each), those covering best
static struct tc_poses poses;
static struct tc_record cal;  // the calibration in use
static bool have_cal, calibrated_output = true;
static unsigned long last_sample, last_print;

static void mpu_write(uint8_t reg, uint8_t value)
{
    Wire.beginTransmission(MPU);
    Wire.write(reg);
    Wire.write(value);
    Wire.endTransmission();
}

// One sample as the still detector wants it: ax ay az gx gy gz temp (counts); false if the
// sensor did not answer.
static bool mpu_read(int16_t v[STILL_CHANNELS])
{
    static const uint8_t order[7] = {0, 1, 2, 4, 5, 6, 3};  // registers: AX AY AZ T GX GY GZ
    uint8_t raw[14];
    Wire.beginTransmission(MPU);
    Wire.write(0x3B);
    if (Wire.endTransmission(false) != 0 || Wire.requestFrom(MPU, (uint8_t)14) != 14) {
        return false;
    }
    for (uint8_t i = 0; i < 14; i++) raw[i] = Wire.read();
    for (uint8_t i = 0; i < 7; i++) {
        v[i] = (int16_t)((raw[2 * order[i]] << 8) | raw[2 * order[i] + 1]);
    }
    return true;
}

static void print3(const __FlashStringHelper *label, const float *x, uint8_t digits)
{
    Serial.print(label);
    for (uint8_t i = 0; i < 3; i++) {
        Serial.print(i ? ", " : " ");
        Serial.print(x[i], digits);
    }
    Serial.println();
}

static void show(const struct tc_record *r)
{
    print3(F("  offset (counts):"), r->offset, 2);
    float gains[3] = {r->matrix[0][0], r->matrix[1][1], r->matrix[2][2]};
    print3(F("  gains (multiply):"), gains, 6);
    Serial.print(F("  RMS "));
    Serial.print(r->rms / COUNTS_PER_G * 1000.0f, 3);
    Serial.print(F(" mg over "));
    Serial.print(r->n);
    Serial.print(F(" poses, coverage "));
    Serial.println(r->spread, 3);
}

static bool load()
{
    uint8_t b[TC_STORE_BYTES];
    for (uint8_t i = 0; i < TC_STORE_BYTES; i++) b[i] = EEPROM.read(EEPROM_AT + i);
    uint8_t st = tc_store_unpack(b, &cal);
    if (st == TC_STORE_OK) return true;
    if (st == TC_STORE_ABSENT) {
        Serial.println(F("no stored calibration"));
    } else {
        Serial.println(F("the stored calibration is damaged or unusable: calibrate again"));
    }
    return false;
}

// The sphere-centre program, the end of it: the centre and the gains, the record.
static void calibrate()
{
    const tc_real(*p)[3] = (const tc_real(*)[3])poses.p;
    struct tc_fit_options fo;
    struct tc_fit f;
    tc_fit_defaults(&fo, TC_MODEL_AXIS, COUNTS_PER_G);
    int8_t code = tc_fit(p, poses.n, &fo, &f);
    if (code != TC_OK) {
        Serial.print(F("the fit refused the poses, code "));  // triaxcal.h: enum tc_code
        Serial.println(code);
        return;
    }
    struct tc_record r;
    memset(&r, 0, sizeof r);
    r.sensor = TC_STORE_SENSOR_ACCEL;
    r.model = TC_MODEL_AXIS;
    r.origin = TC_STORE_ORIGIN_BOARD;
    r.n = f.n;
    r.warnings = f.warnings;
    r.radius = f.radius;
    for (uint8_t i = 0; i < 3; i++) {
        r.offset[i] = f.offset[i];
        for (uint8_t j = 0; j < 3; j++) r.matrix[i][j] = f.matrix[i][j];
    }
    r.rms = f.rms;
    r.spread = f.spread;
    uint8_t b[TC_STORE_BYTES];
    tc_store_pack(&r, b);
    for (uint8_t i = 0; i < TC_STORE_BYTES; i++) EEPROM.update(EEPROM_AT + i, b[i]);
    Serial.println(F("calibrated and stored:"));
    show(&r);
    if (f.warnings) {
        Serial.print(F("  warnings 0x"));  // triaxcal.h: TC_WARN_*
        Serial.println(f.warnings, HEX);
    }
    have_cal = load();
}

void setup()
{
    Serial.begin(115200);
    Wire.begin();
    Wire.setClock(400000);
    mpu_write(0x6B, 0x01);  // wake, clock from the gyro
    mpu_write(0x1A, 0x03);  // low-pass 44 Hz
    mpu_write(0x1B, 0x00);  // +-250 deg/s
    mpu_write(0x1C, 0x00);  // +-2 g: 16384 counts per g
    pinMode(BUZZER_PIN, OUTPUT);
    struct still_settings s;
    still_defaults(&s);  // the sphere-centre method's 0.07 g, 2 s of hold-off, 100 samples per second
    still_start(&s);
    tc_poses_init(&poses, store, 48);
    have_cal = load();
    if (have_cal) {
        Serial.println(F("stored calibration:"));
        show(&cal);
    }
    Serial.println(F("hold the board still in each pose until it beeps; 'c' fits now"));
}

void loop()
{
    while (Serial.available() > 0) {
        char c = Serial.read();
        if (c == 'c') calibrate();
        if (c == 'r' || c == 'a') calibrated_output = c == 'a';
    }
    if (millis() - last_sample < 10) return;  // 100 samples per second
    last_sample = millis();
    int16_t v[STILL_CHANNELS];
    if (!mpu_read(v)) {
        still_break();  // a missing sample is never averaged into a pose
        return;
    }
    if (still_feed(v) & STILL_EV_POSE) {
        tc_real p[3];
        tc_pose_accel(still_pose(), p);
        tc_poses_add(&poses, p);
        tone(BUZZER_PIN, 2000, 100);
        Serial.print(F("pose "));
        Serial.print(poses.seen);
        print3(F(":"), p, 1);
        if (poses.seen == GLOBE_POSES) calibrate();
    }
    if (have_cal && millis() - last_print >= 1000) {
        last_print = millis();
        tc_real raw[3] = {(tc_real)v[0], (tc_real)v[1], (tc_real)v[2]}, g[3];
        if (calibrated_output) {
            tc_apply(cal.offset, cal.matrix, raw, g);
            for (uint8_t i = 0; i < 3; i++) g[i] /= COUNTS_PER_G;
            print3(F("g:"), g, 4);
        } else {
            print3(F("counts:"), raw, 0);
        }
    }
}
