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

/* One word's count: RES 0/1 words are two's complement and RES 2 words unsigned around 2^15, so the count is the word,
 * or the word with its top bit flipped (flip), in 16 bits (short_words); RES 3 words take 32 (counts). */
static int16_t count_of(uint16_t word, uint8_t short_words, uint16_t flip)
{
    return short_words ? (int16_t)(word ^ flip) : clamp16(counts(word));
}

uint8_t mf_sample_words(const mlx_raw_t *raw, int16_t *b)
{
    const int16_t limit = (int16_t)MF_RAW_LIMIT; /* at most 32767: chips.toml's output limits */
    const uint8_t short_words = (uint8_t)(MF_RAW_SIGNED || MF_RAW_ZERO == 32768L);
    const uint16_t flip = MF_RAW_SIGNED ? 0U : 0x8000U;
    uint8_t k;
    b[0] = count_of(raw->x, short_words, flip); /* no array of the words: this runs for every array chip */
    b[1] = count_of(raw->y, short_words, flip);
    b[2] = count_of(raw->z, short_words, flip);
    for (k = 0; k < 3; ++k) {
        if (b[k] >= limit || b[k] <= (int16_t)-limit) { /* a clamped count is past the limit too */
            return MF_FLAG_SATURATED;
        }
    }
    return 0;
}

/* The counts, the saturation flag, the temperature word, NaN forces. */
static void fill_counts(const mlx_raw_t *raw, mf_sample_t *s)
{
    s->flags = mf_sample_words(raw, s->b_counts);
    s->fault = 0;
    s->t_raw = MF_TEMPERATURE ? raw->t : 0U;
    s->f_N[0] = s->f_N[1] = s->f_N[2] = NAN;
}

void mf_sample_counts(const mlx_raw_t *raw, mf_sample_t *s)
{
    fill_counts(raw, s);
    s->b_uT[0] = s->b_uT[1] = s->b_uT[2] = NAN;
    s->t_C = NAN;
}

void mf_sample_convert(const mlx_raw_t *raw, mf_sample_t *s)
{
    fill_counts(raw, s);
    s->b_uT[0] = (float)counts(raw->x) * MF_LSB_XY_UT; /* before the clamp */
    s->b_uT[1] = (float)counts(raw->y) * MF_LSB_XY_UT;
    s->b_uT[2] = (float)counts(raw->z) * MF_LSB_Z_UT;
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
