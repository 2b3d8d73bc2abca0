#include "tc_store.h"

#include <string.h>

#include "crc16.h"

static uint8_t finite32(float x) { return (uint8_t)((x - x) == 0); }

static void put_f32(uint8_t *p, float v)
{
    uint32_t u;
    memcpy(&u, &v, 4); /* IEEE binary32 on every target this runs on */
    for (uint8_t i = 0; i < 4; i++) {
        p[i] = (uint8_t)(u & 0xFF);
        u >>= 8;
    }
}

float tc_store_f32(const uint8_t *p)
{
    uint32_t u = 0;
    for (uint8_t i = 4; i-- > 0;) u = (u << 8) | p[i];
    float v;
    memcpy(&v, &u, 4);
    return v;
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
}

static uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }

void tc_store_pack(const struct tc_record *r, uint8_t out[TC_STORE_BYTES])
{
    out[0] = 'T';
    out[1] = 'C';
    out[2] = TC_STORE_VERSION;
    out[3] = r->sensor;
    out[4] = r->model;
    out[5] = r->origin;
    put_u16(out + 6, r->n);
    put_u16(out + 8, r->warnings);
    put_f32(out + 10, r->radius);
    for (uint8_t i = 0; i < 3; i++) put_f32(out + 14 + 4 * i, r->offset[i]);
    for (uint8_t i = 0; i < 9; i++) put_f32(out + 26 + 4 * i, r->matrix[i / 3][i % 3]);
    put_f32(out + 62, r->rms);
    put_f32(out + 66, r->spread);
    put_u16(out + 70, crc16_ccitt(out, TC_STORE_BYTES - 2));
}

uint8_t tc_store_check(const struct tc_record *r)
{
    if (!finite32(r->radius) || !(r->radius > 0)) return TC_STORE_INVALID;
    for (uint8_t i = 0; i < 3; i++) {
        if (!finite32(r->offset[i])) return TC_STORE_INVALID;
        for (uint8_t j = 0; j < 3; j++) {
            if (!finite32(r->matrix[i][j])) return TC_STORE_INVALID;
        }
    }
    const float(*m)[3] = r->matrix;
    float det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if (!finite32(det) || det == 0) return TC_STORE_INVALID; /* singular: not a calibration */
    if (!finite32(r->rms) || !finite32(r->spread)) return TC_STORE_INVALID;
    return TC_STORE_OK;
}

uint8_t tc_store_unpack(const uint8_t in[TC_STORE_BYTES], struct tc_record *r)
{
    uint8_t all_ff = 1, all_00 = 1;
    for (uint8_t i = 0; i < TC_STORE_BYTES; i++) {
        if (in[i] != 0xFF) all_ff = 0;
        if (in[i] != 0x00) all_00 = 0;
    }
    if (all_ff || all_00) return TC_STORE_ABSENT;
    if (in[0] != 'T' || in[1] != 'C') return TC_STORE_CORRUPT;
    if (crc16_ccitt(in, TC_STORE_BYTES - 2) != get_u16(in + 70)) return TC_STORE_CORRUPT;
    if (in[2] != TC_STORE_VERSION) return TC_STORE_VERSION_UNKNOWN;
    r->sensor = in[3];
    r->model = in[4];
    r->origin = in[5];
    r->n = get_u16(in + 6);
    r->warnings = get_u16(in + 8);
    r->radius = tc_store_f32(in + 10);
    for (uint8_t i = 0; i < 3; i++) r->offset[i] = tc_store_f32(in + 14 + 4 * i);
    for (uint8_t i = 0; i < 9; i++) r->matrix[i / 3][i % 3] = tc_store_f32(in + 26 + 4 * i);
    r->rms = tc_store_f32(in + 62);
    r->spread = tc_store_f32(in + 66);
    return tc_store_check(r);
}
