/* The force calibration (calibration.json; magfab docs/models.md, M12 to M14) evaluated in float32 from the calibration
 * record in EEPROM (docs/bundle.md section 4, mf_nv.h):
 *   B_k <- B_k / (1 + a_k (T - T0)) for k in x, y, z (a version-4 record with the sample's temperature converted),
 *   Br = sqrt(Bx^2 + By^2), u = (Bz - c_z) / s_z, v = (Br - c_r) / s_r,
 *   F = sum c_ij u^i v^j (Horner form) - tare, for F in Fz, Fr,
 *   Fx = shear_sign Fr Bx / Br, Fy = shear_sign Fr By / Br (0 when Br < direction_min_uT),
 * and the valid-region test (box, then the convex hull) that sets MF_FLAG_OUTSIDE.
 * Without a valid record (missing, wrong version or length, bad CRC, settings out of range, or, in a build-specific
 * image, made for other chip settings) there is no force: the loop sends error frames (MF_E_CALIB) until one is
 * uploaded. The generic image (MF_GENERIC) also takes its settings from the record (mf_settings.h). */
#ifndef MF_CALIB_H
#define MF_CALIB_H

#include "mf_sample.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Record layout (readout package eeprom.py): header, the image's settings, the floats, the Horner rows, the hull
 * fan and edges, the spec name, the CRC. */
#define MF_CAL_MAGIC0 'M'
#define MF_CAL_MAGIC1 'F'
#define MF_CAL_VERSION 2
#define MF_CAL_VERSION_THERMAL 4 /* version 2 with the thermal block at MF_CAL_COEF_AT, the Horner rows after it */
#define MF_CAL_VERSION_ARRAY 3 /* an array's record: the settings, the chips' addresses, no calibration */
#define MF_CAL_VERSION_REFERENCE 5 /* version 4 and a reference block after the thermal block, then the Horner rows */
#define MF_CAL_ADDR_AT 92      /* an array record's chip addresses, one byte each in taxel order */
#define MF_MAX_TAXELS 16
#define MF_CAL_BUSES_AT 6 /* an array record's buses: bit k set for taxel k on the second I2C bus (uint16) */
#ifndef MF_BUSES
#define MF_BUSES 1 /* the I2C buses the image drives (-DMF_BUSES=2: a board with a second controller wired) */
#endif
#define MF_CAL_SHA_AT 8      /* 16 ASCII hex digits of the calibration's sha256 */
#define MF_CAL_SETTINGS_AT 24 /* gain_sel, resolution, osr, dig_filt the record was made for */
#define MF_CAL_IMAGE_AT 28   /* the image's settings: mf_settings_t's fields in order, packed */
#define MF_CAL_FLOATS_AT 92
#define MF_CAL_COEF_AT 164
#define MF_CAL_THERMAL_LEN 16 /* version 4: T0 (degC), then a_x, a_y, a_z (1/degC), float32 each */
#define MF_CAL_REFERENCE_LEN 4 /* version 5: the reference chip's 7-bit address, the average's shift, two zeros */
#define MF_CAL_MAX_ORDER 8
#define MF_CAL_NAME_MAX 64

/* Read and check the record (MF_OK or MF_E_CALIB); call at start-up and after every write. */
int mf_calib_load(void);
/* MF_OK when the last load found a valid record. */
int mf_calib_status(void);
/* An array's valid record: its number of chips (1..MF_MAX_TAXELS); 0 for a single taxel's or none. */
uint8_t mf_calib_taxels(void);
/* A version-5 record's reference chip: its 7-bit address (0: none) and its average's shift (1..8). */
uint8_t mf_calib_reference(void);
uint8_t mf_calib_reference_shift(void);
/* The 7-bit I2C address of taxel k (k < mf_calib_taxels()). */
uint8_t mf_calib_address(uint8_t k);
/* The I2C bus of taxel k: 0, or 1 for the second (an array record whose buses mask has bit k set; an image of one
 * bus refuses a record that names a second). */
uint8_t mf_calib_bus(uint8_t k);
/* Byte k (0..15) of the record's calibration hash, for the info line ('0' without a valid record). */
char mf_calib_sha(uint8_t k);
/* Byte k (0..3) of the chip settings the record was made for: gain_sel, resolution, osr, dig_filt (0 without). */
uint8_t mf_calib_setting(uint8_t k);
/* The spec name's length in bytes and byte k of it (empty without a valid record). */
uint8_t mf_calib_name_len(void);
char mf_calib_name(uint8_t k);
/* Forces of a converted sample (b_uT set, left as read); adds MF_FLAG_OUTSIDE outside the calibrated region. A
 * version-4 record's thermal correction applies when the sample carries a temperature (t_C not NaN) at which every
 * denominator 1 + a (T - T0) is at least 0.5 (a record is refused unless it is so from -40 to 125 degC); at another
 * the field is left uncorrected and MF_FLAG_OUTSIDE set. Only with a valid record (mf_calib_status() == MF_OK). */
void mf_calib_forces(mf_sample_t *s);
/* 1 when (Bz, Br) in microtesla lies in the calibrated region: inside the box and the hull, edges included. */
uint8_t mf_calib_inside(float bz, float br);

#ifdef __cplusplus
}
#endif

#endif
