#include "board_cal.h"

#include <string.h>

#include "nvstore.h"
#include "triaxcal.h"

TC_POSES_STORAGE(pose_store, CAL_POSES);
static struct tc_poses poses;
static uint8_t cal_ok; /* storage holds a good record */
static uint8_t applying;
static uint8_t fitted_this_run;

/* Check what storage holds. */
static void load(void)
{
    uint8_t b[TC_STORE_BYTES];
    struct tc_record r;
    nv_read(NV_RECORD_ADDR, b, TC_STORE_BYTES);
    cal_ok = tc_store_unpack(b, &r) == TC_STORE_OK && r.sensor == TC_STORE_SENSOR_ACCEL;
    if (!cal_ok) applying = 0;
}

void cal_init(void)
{
    tc_poses_init(&poses, pose_store, CAL_POSES);
    applying = 0;
    load();
}

void cal_start(void)
{
    tc_poses_init(&poses, pose_store, CAL_POSES);
    fitted_this_run = 0;
}

uint8_t cal_pose(const struct still_pose *pose)
{
    tc_real p[3];
    tc_pose_accel(pose, p);
    tc_poses_add(&poses, p);
    if (poses.seen >= CAL_AUTO_POSES && !fitted_this_run) {
        fitted_this_run = 1;
        return 1;
    }
    return 0;
}

/* Write a record's bytes and read them back: 1 when storage holds them and they are good. */
static uint8_t store(const uint8_t b[TC_STORE_BYTES])
{
    nv_write(NV_RECORD_ADDR, b, TC_STORE_BYTES);
    uint8_t same = 1;
    for (uint8_t i = 0; i < TC_STORE_BYTES; i++) {
        uint8_t back;
        nv_read((uint16_t)(NV_RECORD_ADDR + i), &back, 1);
        if (back != b[i]) same = 0;
    }
    load();
    return same && cal_ok;
}

/* The sphere-centre method's search for the centre of the sphere of radius CAL_RADIUS, into q. */
static void descend(const tc_real (*pts)[3], struct proto_quality *q)
{
    struct tc_descent_options o;
    struct tc_descent d;
    tc_descent_defaults(&o);
    q->descent_code = tc_descend_center(pts, poses.n, CAL_RADIUS, &o, &d);
    if (q->descent_code) return;
    for (uint8_t k = 0; k < 3; k++) q->center[k] = (float)d.center[k];
    q->descent_iterations = d.iterations > 65535u ? 65535u : (uint16_t)d.iterations;
}

/* The record of a fit made on the board, as its bytes. */
static void record_of(const struct tc_fit *f, uint8_t b[TC_STORE_BYTES])
{
    struct tc_record r;
    memset(&r, 0, sizeof r);
    r.sensor = TC_STORE_SENSOR_ACCEL;
    r.model = TC_MODEL_AXIS;
    r.origin = TC_STORE_ORIGIN_BOARD;
    r.n = f->n;
    r.warnings = f->warnings;
    r.radius = (float)f->radius;
    for (uint8_t i = 0; i < 3; i++) {
        r.offset[i] = (float)f->offset[i];
        for (uint8_t j = 0; j < 3; j++) r.matrix[i][j] = (float)f->matrix[i][j];
    }
    r.rms = (float)f->rms;
    r.spread = (float)f->spread;
    tc_store_pack(&r, b);
}

/* Store a fit made on the board (the record is built in a frame of its own, gone before the
 * bytes are written and checked: the stack stays within the fit's own depth). */
static uint8_t store_fit(const struct tc_fit *f)
{
    uint8_t b[TC_STORE_BYTES];
    record_of(f, b);
    return store(b);
}

/* The centre and the gains: offset + 3 gains, as the host's "axis" model; stored when the
 * fit passes. (A function of its own: its result is not on the stack during the search.) */
static int8_t fit(struct proto_quality *q)
{
    const tc_real(*pts)[3] = (const tc_real(*)[3])poses.p;
    struct tc_fit_options fo;
    struct tc_fit f;
    tc_fit_defaults(&fo, TC_MODEL_AXIS, CAL_RADIUS);
    q->code = tc_fit(pts, poses.n, &fo, &f);
    q->iterations = f.iterations;
    q->stack_free = cal_stack_free();
    if (q->code) return q->code;
    q->warnings = f.warnings;
    q->rms = (float)f.rms;
    q->spread = (float)f.spread;
    for (uint8_t k = 0; k < 6; k++) q->faces[k] = f.faces[k] > 255 ? 255 : (uint8_t)f.faces[k];
    if (!store_fit(&f)) return q->code = CAL_ERR_STORAGE;
    applying = 1;
    return TC_OK;
}

int8_t cal_compute(struct proto_quality *q)
{
    memset(q, 0, sizeof *q);
    q->n = poses.n;
    descend((const tc_real(*)[3])poses.p, q);
    return fit(q);
}

uint8_t cal_write(const uint8_t record[TC_STORE_BYTES])
{
    struct tc_record r;
    uint8_t st = tc_store_unpack(record, &r);
    if (st != TC_STORE_OK) return st;
    if (r.sensor != TC_STORE_SENSOR_ACCEL) return TC_STORE_INVALID; /* not this board's sensor */
    return store(record) ? TC_STORE_OK : TC_STORE_CORRUPT;
}

#if SIMULATED
void cal_damage(void)
{
    nv_damage(NV_RECORD_ADDR + 20); /* a bit of the offset: the CRC no longer matches */
    load();
}
#endif

void cal_set_apply(uint8_t on) { applying = on && cal_ok; }

uint8_t cal_applied(void) { return applying; }

uint8_t cal_stored(uint8_t out[TC_STORE_BYTES])
{
    struct tc_record r;
    nv_read(NV_RECORD_ADDR, out, TC_STORE_BYTES);
    return tc_store_unpack(out, &r);
}

void cal_apply(int16_t *v)
{
    if (!applying) return;
    /* the offsets and the matrix, read from storage each time (48 bytes: no RAM is kept for
     * them; the record was checked when it was stored or at boot) */
    uint8_t b[48];
    tc_real off[3], m[3][3];
    nv_read(NV_RECORD_ADDR + TC_STORE_AT_OFFSET, b, sizeof b);
    for (uint8_t i = 0; i < 3; i++) {
        off[i] = tc_store_f32(b + 4 * i);
        for (uint8_t j = 0; j < 3; j++) m[i][j] = tc_store_f32(b + 12 + 12 * i + 4 * j);
    }
    tc_apply_counts(off, (const tc_real(*)[3])m, v, v);
}

#if defined(__AVR__)
/* Stack painting: at start-up (.init1, before the C runtime) every byte between the end of
 * .bss and the stack pointer is set to STACK_PAINT; the lowest byte that still holds it is as
 * deep as the stack ever went. */
#include <avr/io.h>
#define STACK_PAINT 0xC5
extern uint8_t __heap_start;

void cal_paint_stack(void) __attribute__((naked, used, section(".init1")));
void cal_paint_stack(void)
{
    __asm__ volatile(
        "    ldi r30, lo8(__heap_start)\n"
        "    ldi r31, hi8(__heap_start)\n"
        "    ldi r24, %0\n"
        "    ldi r25, hi8(%1)\n"
        "1:  st Z+, r24\n"
        "    cpi r30, lo8(%1)\n"
        "    cpc r31, r25\n"
        "    brlo 1b\n"
        :
        : "i"(STACK_PAINT), "i"(RAMEND - 32));
}

uint16_t cal_stack_free(void)
{
    const uint8_t *p = &__heap_start;
    uint16_t n = 0;
    while (p < (const uint8_t *)(RAMEND - 32) && *p == STACK_PAINT) {
        p++;
        n++;
    }
    return n;
}
#else
uint16_t cal_stack_free(void) { return 0; }
#endif
