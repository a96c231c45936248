/* One sample: raw counts to microtesla (with the RES 2/3 offsets), the saturation flag, and the forces. */
#ifndef MF_SAMPLE_H
#define MF_SAMPLE_H

#include <stdint.h>

#include "mlx90393.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Status flags of a frame (docs/bundle.md section 3). */
#define MF_FLAG_OUTSIDE 0x01    /* the reading lies outside the calibrated region */
#define MF_FLAG_CHIP_ERROR 0x02 /* NACK, ERROR bit, wrong byte count or timeout: the forces are NaN */
#define MF_FLAG_SATURATED 0x04  /* a field axis at the chip's output limit */
#define MF_FLAG_RECOVERED 0x08  /* the chip was reset since the last frame */

/* Where a fault struck, the high byte of a failed sample's fault word (its low byte is -MF_E_*). */
#define MF_STAGE_READ 1  /* reading the sample (RM, or SM and RM) */
#define MF_STAGE_START 2 /* starting the chip: boot, or the recovery after a failed sample, all attempts failed */
#define MF_STAGE_EEPROM 3 /* the calibration record (the chip was read fine) */

typedef struct mf_sample {
    uint8_t flags;
    int16_t b_counts[3]; /* X, Y, Z counts, RES offsets removed (0 on a chip error) */
    uint16_t t_raw;      /* raw temperature word (0 when not converted or on a chip error) */
    uint16_t fault;      /* on a chip error: MF_STAGE_* << 8 | -MF_E_*; 0 otherwise */
    float b_uT[3];       /* X, Y, Z field, microtesla (NaN on a chip error) */
    float t_C;           /* chip temperature, degC (NaN when not converted or on a chip error) */
    float f_N[3];        /* Fx, Fy, Fz, newton (NaN on a chip error) */
} mf_sample_t;

/* Counts and microtesla from the raw words; sets MF_FLAG_SATURATED, clears the other flags and the forces. */
void mf_sample_convert(const mlx_raw_t *raw, mf_sample_t *s);
/* The same without floating point: the counts, the flag and the temperature word, NaN microtesla and temperature
 * (what an array's binary field frame and the reference chip's average use: about 60 us less on the AVR). */
void mf_sample_counts(const mlx_raw_t *raw, mf_sample_t *s);
/* The X, Y, Z counts of raw's words (RES offsets removed, clamped to 16 bits) into b, and MF_FLAG_SATURATED when one
 * is at the chip's output limit (else 0): the counts an array's binary cycle frame carries, without a sample. */
uint8_t mf_sample_words(const mlx_raw_t *raw, int16_t *b);
/* A sample that failed with error rc (MF_E_*) at stage (MF_STAGE_*): chip-error flag, the fault word, zero
 * counts, NaN everywhere else. */
void mf_sample_fail(mf_sample_t *s, int rc, uint8_t stage);

#ifdef __cplusplus
}
#endif

#endif
