/* The pose buffer (triaxcal.h): every pose while there is room, then the ones that cover the
 * sphere. */
#include <string.h>

#include "tc_internal.h"

void tc_poses_init(struct tc_poses *b, tc_real (*storage)[3], uint16_t capacity)
{
    memset(b, 0, sizeof *b);
    b->p = storage;
    b->capacity = capacity;
}

void tc_pose_accel(const struct still_pose *pose, tc_real out[3])
{
    for (uint8_t k = 0; k < 3; k++) {
        out[k] = pose->n ? (tc_real)pose->sum[k] / (tc_real)pose->n : 0;
    }
}

static tc_real dist2(const tc_real a[3], const tc_real b[3])
{
    tc_real x = a[0] - b[0], y = a[1] - b[1], z = a[2] - b[2];
    return x * x + y * y + z * z;
}

/* Smallest squared distance from p to a stored pose other than skip (and skip2). */
static tc_real nearest2(const struct tc_poses *b, const tc_real p[3], uint16_t skip,
                        uint16_t skip2)
{
    tc_real best = -1;
    for (uint16_t i = 0; i < b->n; i++) {
        if (i == skip || i == skip2) continue;
        tc_real d = dist2(p, b->p[i]);
        if (best < 0 || d < best) best = d;
    }
    return best;
}

/* The closest pair of stored poses: its squared distance, its two indices in *a < *c. */
static tc_real closest_pair(const struct tc_poses *b, uint16_t *a, uint16_t *c)
{
    tc_real best = -1;
    *a = *c = 0;
    for (uint16_t i = 0; i < b->n; i++) {
        for (uint16_t j = (uint16_t)(i + 1); j < b->n; j++) {
            tc_real d = dist2(b->p[i], b->p[j]);
            if (best < 0 || d < best) {
                best = d;
                *a = i;
                *c = j;
            }
        }
    }
    return best;
}

tc_real tc_poses_min_gap2(const struct tc_poses *b)
{
    uint16_t i, j;
    tc_real d = closest_pair(b, &i, &j);
    return d < 0 ? 0 : d;
}

int16_t tc_poses_add(struct tc_poses *b, const tc_real p[3])
{
    uint8_t k;
    for (k = 0; k < 3; k++) {
        if (!tc_finite(p[k])) return TC_POSE_DROPPED; /* never store what cannot be fitted */
    }
    if (b->seen < UINT16_MAX) b->seen++;
    if (b->capacity < 3) return TC_POSE_DROPPED; /* no pair to choose between */
    if (b->n < b->capacity) {
        for (k = 0; k < 3; k++) b->p[b->n][k] = p[k];
        return (int16_t)b->n++;
    }
    uint16_t i, j;
    tc_real gap = closest_pair(b, &i, &j);
    if (!(nearest2(b, p, UINT16_MAX, UINT16_MAX) > gap)) return TC_POSE_DROPPED;
    /* of the closest two, give up the one whose other neighbours are nearer (the more crowded
     * place); ties: the older one */
    uint16_t out = nearest2(b, b->p[j], i, j) < nearest2(b, b->p[i], i, j) ? j : i;
    for (k = 0; k < 3; k++) b->p[out][k] = p[k];
    if (b->replaced < UINT16_MAX) b->replaced++;
    return (int16_t)out;
}
