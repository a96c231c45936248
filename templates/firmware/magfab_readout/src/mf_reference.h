/* The reference chip (a version-5 record's, docs/bundle.md section 4): an MLX90393 on the board that no magnet
 * moves. It is started with the sensing chip and read after it every other sample (in burst mode its latest
 * conversion, always complete by then, its RM chained behind the sensing chip's on a HAL that can: the bus reads
 * both while the sample before is worked out; in single mode the SM sent the sample before); its change since its first
 * reading, low-passed (an exponential average of 2^shift readings: stray fields move slower than a few hertz, and
 * the average keeps the reference's own noise out), is subtracted from the sensing chip's counts before anything
 * else, so the frame's field, the temperature correction and the calibration all see the corrected field. A failed
 * read keeps the average as it was and restarts the chip at most every MF_LOST_RETRY_US. */
#ifndef MF_REFERENCE_H
#define MF_REFERENCE_H

#include "mf_app.h"

#ifdef __cplusplus
extern "C" {
#endif

/* (Re)start the reference chip when the record has one (the average starts again from its next reading). */
void mf_ref_start(mf_app_t *a);
/* Every other call: read the reference chip and update the average (single mode: the call between sends its SM).
 * Its RM is the one chained behind the sensing chip's when that started (mf_app_queue, a->chained). */
void mf_ref_update(mf_app_t *a);
/* The reference chip's address when the next mf_ref_update reads it in burst mode (then its RM can be queued behind
 * the sensing chip's: mf_app_queue), else 0. */
uint8_t mf_ref_due(void);
/* Start it again from the next sample on (a new record was written). */
void mf_ref_reset(const mf_app_t *a);
/* Subtract the reference's averaged change from a converted sample's counts and field (nothing without one). */
void mf_ref_apply(mf_sample_t *s);

#ifdef __cplusplus
}
#endif

#endif
