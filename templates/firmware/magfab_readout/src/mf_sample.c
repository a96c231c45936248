/* Raw words to counts and microtesla for the configured GAIN_SEL and RES (mf_config.h). */
#include "mf_sample.h"

#include <math.h>

#include "mf_config.h"

/* Counts with the RES offset removed: RES 0/1 words are two's complement, RES 2/3 words are unsigned
 * around 2^15 / 2^14 (TCMP off). */
static int32_t counts(uint16_t word)
{
    if (MF_RAW_SIGNED) {
        return word >= 0x8000U ? (int32_t)word - 65536L : (int32_t)word;
    }
    return (int32_t)word - MF_RAW_ZERO;
}

static int16_t clamp16(int32_t c)
{
    if (c > 32767L) {
        return 32767;
    }
    if (c < -32768L) {
        return (int16_t)-32768L;
    }
    return (int16_t)c;
}

/* The counts (c: before the clamp), the saturation flag, the temperature word, NaN forces. */
static void fill_counts(const mlx_raw_t *raw, mf_sample_t *s, int32_t *c)
{
    uint8_t k;
    c[0] = counts(raw->x);
    c[1] = counts(raw->y);
    c[2] = counts(raw->z);
    s->flags = 0;
    s->fault = 0;
    for (k = 0; k < 3; ++k) {
        if (c[k] >= MF_RAW_LIMIT || c[k] <= -MF_RAW_LIMIT) {
            s->flags |= MF_FLAG_SATURATED;
        }
        s->b_counts[k] = clamp16(c[k]);
    }
    s->t_raw = MF_TEMPERATURE ? raw->t : 0U;
    s->f_N[0] = s->f_N[1] = s->f_N[2] = NAN;
}

void mf_sample_counts(const mlx_raw_t *raw, mf_sample_t *s)
{
    int32_t c[3];
    fill_counts(raw, s, c);
    s->b_uT[0] = s->b_uT[1] = s->b_uT[2] = NAN;
    s->t_C = NAN;
}

void mf_sample_convert(const mlx_raw_t *raw, mf_sample_t *s)
{
    int32_t c[3];
    fill_counts(raw, s, c);
    s->b_uT[0] = (float)c[0] * MF_LSB_XY_UT;
    s->b_uT[1] = (float)c[1] * MF_LSB_XY_UT;
    s->b_uT[2] = (float)c[2] * MF_LSB_Z_UT;
    s->t_C = MF_TEMPERATURE ? 25.0f + (float)((int32_t)raw->t - MF_T_RAW_25C) * MF_T_C_PER_LSB : NAN;
}

void mf_sample_fail(mf_sample_t *s, int rc, uint8_t stage)
{
    uint8_t k;
    s->flags = MF_FLAG_CHIP_ERROR;
    s->fault = (uint16_t)((uint16_t)stage << 8 | (uint8_t)(-rc));
    s->t_raw = 0;
    s->t_C = NAN;
    for (k = 0; k < 3; ++k) {
        s->b_counts[k] = 0;
        s->b_uT[k] = NAN;
        s->f_N[k] = NAN;
    }
}
