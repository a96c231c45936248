/* The force calibration (calibration.json, eq. 12-14 of the brief) evaluated in float32:
 *   Br = sqrt(Bx^2 + By^2), u = (Bz - c_z) / s_z, v = (Br - c_r) / s_r,
 *   F = sum c_ij u^i v^j (Horner form) - tare, for F in Fz, Fr,
 *   Fx = shear_sign Fr Bx / Br, Fy = shear_sign Fr By / Br (0 when Br < direction_min_uT),
 * and the valid-region test (box, then the convex hull) that sets MF_FLAG_OUTSIDE. */
#ifndef MF_CALIB_H
#define MF_CALIB_H

#include "mf_sample.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Forces of a converted sample (b_uT set); adds MF_FLAG_OUTSIDE outside the calibrated region. */
void mf_calib_forces(mf_sample_t *s);
/* 1 when (Bz, Br) in microtesla lies in the calibrated region: inside the box and the hull, edges included. */
uint8_t mf_calib_inside(float bz, float br);

#ifdef __cplusplus
}
#endif

#endif
