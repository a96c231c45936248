/* Calibration evaluation: see mf_calib.h. The polynomial (unrolled, constants in the code) and the region
 * tables (flash on AVR) come from mf_calib_data.h. */
#include "mf_calib.h"

#include <math.h>

#include "mf_calib_data.h"
#include "mf_rom.h"

#define FAN_Z(k) mf_rom_float(&mf_cal_fan[2 * (k)])
#define FAN_R(k) mf_rom_float(&mf_cal_fan[2 * (k) + 1])

/* Left of p_0 -> p_k (q relative to p_0), > 0; on it, 0. */
static float fan_side(uint16_t k, float qz, float qr)
{
    return FAN_Z(k) * qr - FAN_R(k) * qz;
}

uint8_t mf_calib_inside(float bz, float br)
{
    float qz, qr;
    const float *e;
    uint16_t lo, hi;
    if (!(bz >= MF_CAL_BZ_LO && bz <= MF_CAL_BZ_HI && br >= MF_CAL_BR_LO && br <= MF_CAL_BR_HI)) {
        return 0; /* outside the box, or NaN */
    }
    if (bz >= MF_CAL_IN_BZ_LO && bz <= MF_CAL_IN_BZ_HI && br >= MF_CAL_IN_BR_LO && br <= MF_CAL_IN_BR_HI) {
        return 1;
    }
    /* Convex hull: find the fan wedge (p_0, p_k, p_k+1) holding q by bisection, then test its outer edge.
     * O(log N) products, so a long hull costs little more than a short one. */
    qz = bz - MF_CAL_P0_BZ;
    qr = br - MF_CAL_P0_BR;
    if (fan_side(1, qz, qr) < 0.0f || fan_side(MF_CAL_HULL_N - 1, qz, qr) > 0.0f) {
        return 0;
    }
    lo = 1;
    hi = MF_CAL_HULL_N - 1;
    while ((uint16_t)(hi - lo) > 1U) {
        uint16_t mid = (uint16_t)((lo + hi) / 2U);
        if (fan_side(mid, qz, qr) >= 0.0f) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    e = &mf_cal_edge[3 * lo];
    return mf_rom_float(&e[0]) * bz + mf_rom_float(&e[1]) * br >= mf_rom_float(&e[2]) ? 1 : 0;
}

void mf_calib_forces(mf_sample_t *s)
{
    float bx = s->b_uT[0];
    float by = s->b_uT[1];
    float bz = s->b_uT[2];
    float br = sqrtf(bx * bx + by * by);
    float fz, fr;
    mf_cal_poly((bz - MF_CAL_BZ_CENTER) * MF_CAL_BZ_INV_SCALE, (br - MF_CAL_BR_CENTER) * MF_CAL_BR_INV_SCALE, &fz, &fr);
    fz -= MF_CAL_TARE_FZ;
    fr -= MF_CAL_TARE_FR;
    if (br >= MF_CAL_DIRECTION_MIN_UT && br > 0.0f) {
        float k = MF_CAL_SHEAR_SIGN * fr / br;
        s->f_N[0] = k * bx;
        s->f_N[1] = k * by;
    } else {
        s->f_N[0] = 0.0f;
        s->f_N[1] = 0.0f;
    }
    s->f_N[2] = fz;
    if (!mf_calib_inside(bz, br)) {
        s->flags |= MF_FLAG_OUTSIDE;
    }
}
