/* Calibration evaluation from the EEPROM record: see mf_calib.h. The record's scalars and coefficients are copied
 * to RAM when it is loaded (every sample needs all of them; 360 B at order 8; a version-4 record's thermal block
 * 16 B more); the hull tables are read from
 * EEPROM as the region test needs them (a few entries per reading, and only near the region's edge). */
#include "mf_calib.h"

#include <float.h>
#include <math.h>

#include "mf_config.h"
#include "mf_errors.h"
#include "mf_frame.h"
#include "mf_nv.h"

#if MF_GENERIC
mf_settings_t mf_set = {0, 0, 0, 0, 0, 0, MF_FALLBACK_UBRR, MF_FALLBACK_BAUD, 0, 0, {0, 0, 0}, {0, 0, 0},
                        0, 0, 0, 0, 0, 0, 0, 0.0f, 0.0f, 0.0f};
#endif

enum { BZ_CENTER, BZ_INV_SCALE, BR_CENTER, BR_INV_SCALE, SHEAR_SIGN, DIRECTION_MIN, TARE_FZ, TARE_FR, BZ_LO, BZ_HI,
       BR_LO, BR_HI, IN_BZ_LO, IN_BZ_HI, IN_BR_LO, IN_BR_HI, P0_BZ, P0_BR, N_FLOATS };

static struct {
    int8_t status;
    uint8_t order;
    uint16_t hull_n;
    uint16_t fan_at;  /* EEPROM address of the fan: (dz, dr) per hull point */
    uint16_t edge_at; /* and of the edge lines: (ex, ey, c) per hull point */
    uint16_t name_at; /* and of the spec name */
    uint8_t name_len;
    uint8_t taxels; /* an array's record (version 3): its chips; 0 for a single taxel's */
    uint16_t buses; /* and their buses: bit k for taxel k on the second */
    uint8_t thermal; /* a version-4 record: the field is corrected for temperature before the calibration */
    uint8_t reference; /* a version-5 record: the reference chip's address (0: none) */
    uint8_t reference_shift;
    float t0_C;      /* the calibration's temperature */
    float a_per_C[3]; /* per axis: the magnet's remanence coefficient plus the chip's sensitivity drift */
    float f[N_FLOATS];
    float coef[(MF_CAL_MAX_ORDER + 1) * (MF_CAL_MAX_ORDER + 2)]; /* the Horner rows, as in the record */
} cal = {MF_E_CALIB, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.0f, {0}, {0}, {0}};

/* What the formula computes, bounded as calibration_json.check_formula bounds it (magfab docs/bundle.md section 2):
 * the least thermal denominator 1 + a (T - T0) over the chip's rated range, the scaled inputs' reach over the valid
 * region's bounding box, and the sum of |c| max(1, |u|)^i max(1, |v|)^j (every Horner partial sum's bound). */
#define MF_THERMAL_MIN_DEN 0.5f
#define MF_T_MIN_C (-40.0f)
#define MF_T_MAX_C 125.0f
#define MF_INPUT_MAX 1000.0f
#define MF_FORCE_MAX_N 1e30f

static uint16_t record_crc(uint16_t len)
{
    uint8_t chunk[16];
    uint16_t crc = 0xFFFF;
    uint16_t a = 0;
    while (a < len) {
        uint16_t left = (uint16_t)(len - a);
        uint8_t n = (uint8_t)(left < (uint16_t)sizeof chunk ? left : (uint16_t)sizeof chunk);
        uint8_t k;
        for (k = 0; k < n; ++k) {
            chunk[k] = mf_nv_byte((uint16_t)(a + k));
        }
        crc = mf_crc16_update(crc, chunk, n);
        a = (uint16_t)(a + n);
    }
    return crc;
}

#if MF_GENERIC
/* The image's settings from a record whose CRC is right; MF_E_CALIB for values no magfab build writes. */
static int load_settings(void)
{
    uint16_t a = MF_CAL_IMAGE_AT;
    uint8_t k;
    mf_set.i2c_address = mf_nv_byte(a);
    mf_set.twbr = mf_nv_byte((uint16_t)(a + 1));
    mf_set.twps_bits = mf_nv_byte((uint16_t)(a + 2));
    mf_set.flags = mf_nv_byte((uint16_t)(a + 3));
    mf_set.zyxt = mf_nv_byte((uint16_t)(a + 4));
    mf_set.name_len = mf_nv_byte((uint16_t)(a + 5));
    mf_set.ubrr = mf_nv_u16((uint16_t)(a + 6));
    mf_set.baud = mf_nv_u32((uint16_t)(a + 8));
    mf_set.i2c_hz = mf_nv_u32((uint16_t)(a + 12));
    mf_set.i2c_timeout_us = mf_nv_u16((uint16_t)(a + 16));
    for (k = 0; k < 3; ++k) {
        mf_set.reg_mask[k] = mf_nv_u16((uint16_t)(a + 18 + 4 * k));
        mf_set.reg_value[k] = mf_nv_u16((uint16_t)(a + 20 + 4 * k));
    }
    mf_set.tconv_us = mf_nv_u32((uint16_t)(a + 30));
    mf_set.read_margin_us = mf_nv_u32((uint16_t)(a + 34));
    mf_set.retry_us = mf_nv_u32((uint16_t)(a + 38));
    mf_set.exit_wait_us = mf_nv_u32((uint16_t)(a + 42));
    mf_set.raw_zero = mf_nv_u16((uint16_t)(a + 46));
    mf_set.raw_limit = mf_nv_u16((uint16_t)(a + 48));
    mf_set.t_raw_25c = mf_nv_u16((uint16_t)(a + 50));
    mf_set.lsb_xy_uT = mf_nv_float((uint16_t)(a + 52));
    mf_set.lsb_z_uT = mf_nv_float((uint16_t)(a + 56));
    mf_set.t_c_per_lsb = mf_nv_float((uint16_t)(a + 60));
    if (mf_set.i2c_address < 0x08U || mf_set.i2c_address > 0x77U || mf_set.twps_bits > 3U || mf_set.ubrr > 4095U
        || (mf_set.zyxt & 0x0EU) != 0x0EU || mf_set.zyxt > 0x0FU || mf_set.tconv_us == 0UL
        || mf_set.i2c_hz == 0UL || mf_set.baud == 0UL || mf_set.raw_limit == 0U
        || !(mf_set.lsb_xy_uT > 0.0f) || !(mf_set.lsb_z_uT > 0.0f)) {
        return MF_E_CALIB;
    }
    return MF_OK;
}
#endif

/* The settings of a record whose length and CRC are right: the generic image's loaded (MF_E_CALIB for values no
 * build writes), a build-specific image's compared with its own chip settings. */
static int record_settings(void)
{
#if MF_GENERIC
    if (load_settings() != MF_OK) {
        mf_set.ubrr = MF_FALLBACK_UBRR;
        mf_set.baud = MF_FALLBACK_BAUD;
        return MF_E_CALIB;
    }
#else
    if (mf_nv_byte(MF_CAL_SETTINGS_AT) != MF_GAIN_SEL || mf_nv_byte(MF_CAL_SETTINGS_AT + 1) != MF_RESOLUTION
        || mf_nv_byte(MF_CAL_SETTINGS_AT + 2) != MF_OSR || mf_nv_byte(MF_CAL_SETTINGS_AT + 3) != MF_DIG_FILT) {
        return MF_E_CALIB; /* made for other chip settings: its microtesla would be wrong */
    }
#endif
    return MF_OK;
}

/* An array's record (version 3): the settings, N chip addresses, the name; no calibration. Its buses mask names no
 * taxel past the N-th, and no second bus for an image of one. */
static int load_array(uint16_t len, uint8_t name_len)
{
    uint8_t n = mf_nv_byte(3);
    uint16_t buses = mf_nv_u16(MF_CAL_BUSES_AT);
    uint8_t k;
    if (n == 0 || n > MF_MAX_TAXELS || len != (uint16_t)(MF_CAL_ADDR_AT + 2U + (uint16_t)n + (uint16_t)name_len)
        || record_crc((uint16_t)(len - 2)) != mf_nv_u16((uint16_t)(len - 2)) || record_settings() != MF_OK
        || (MF_BUSES < 2 && buses != 0U) || (n < 16U && (buses >> n) != 0U)) {
        return MF_E_CALIB;
    }
    for (k = 0; k < n; ++k) {
        uint8_t addr = mf_nv_byte((uint16_t)(MF_CAL_ADDR_AT + k));
        if (addr < 0x08U || addr > 0x77U) {
            return MF_E_CALIB;
        }
    }
    cal.taxels = n;
    cal.buses = buses;
    cal.name_at = (uint16_t)(MF_CAL_ADDR_AT + n);
    cal.name_len = name_len;
    cal.status = MF_OK;
    return MF_OK;
}

#define FAN_Z(k) mf_nv_float((uint16_t)(cal.fan_at + 8U * (k)))
#define FAN_R(k) mf_nv_float((uint16_t)(cal.fan_at + 8U * (k) + 4U))

static uint8_t finite_f(float x)
{
    return (uint8_t)(x >= -FLT_MAX && x <= FLT_MAX); /* 0 for NaN and infinities */
}

/* The largest |(x - centre) inv_scale| over [lo, hi], at least 1 (MF_INPUT_MAX + 1 when it exceeds MF_INPUT_MAX,
 * or for a centre or reciprocal scale that is not finite and positive). */
static float reach(float lo, float hi, float centre, float inv_scale)
{
    float a = fabsf(lo - centre) * inv_scale;
    float b = fabsf(hi - centre) * inv_scale;
    float r = a > b ? a : b;
    if (!finite_f(centre) || !(inv_scale > 0.0f) || !finite_f(inv_scale) || !(r <= MF_INPUT_MAX)) {
        return MF_INPUT_MAX + 1.0f;
    }
    return r > 1.0f ? r : 1.0f;
}

/* MF_OK when the loaded record's formula stays bounded (above), MF_E_CALIB when not: a record no calibration.json
 * that magfab accepts packs to. */
static int record_bounded(void)
{
    float lo[2], hi[2], pu[MF_CAL_MAX_ORDER + 1], pv[MF_CAL_MAX_ORDER + 1], sz = 0.0f, sr = 0.0f;
    const float *c = cal.coef;
    uint16_t k;
    uint8_t m, j;
    if (cal.thermal) {
        for (k = 0; k < 3U; ++k) {
            float a = cal.a_per_C[k];
            if (!(1.0f + a * (MF_T_MIN_C - cal.t0_C) >= MF_THERMAL_MIN_DEN)
                || !(1.0f + a * (MF_T_MAX_C - cal.t0_C) >= MF_THERMAL_MIN_DEN)) {
                return MF_E_CALIB;
            }
        }
    }
    /* the valid region's bounding box: the box clipped to the hull's (the hull's alone when they do not overlap) */
    lo[0] = hi[0] = cal.f[P0_BZ];
    lo[1] = hi[1] = cal.f[P0_BR];
    for (k = 1; k < cal.hull_n; ++k) {
        float z = cal.f[P0_BZ] + FAN_Z(k);
        float r = cal.f[P0_BR] + FAN_R(k);
        lo[0] = z < lo[0] ? z : lo[0];
        hi[0] = z > hi[0] ? z : hi[0];
        lo[1] = r < lo[1] ? r : lo[1];
        hi[1] = r > hi[1] ? r : hi[1];
    }
    for (k = 0; k < 2U; ++k) {
        float blo = cal.f[k ? BR_LO : BZ_LO], bhi = cal.f[k ? BR_HI : BZ_HI];
        float l = blo > lo[k] ? blo : lo[k], h = bhi < hi[k] ? bhi : hi[k];
        if (l <= h) {
            lo[k] = l;
            hi[k] = h;
        }
    }
    pu[0] = reach(lo[0], hi[0], cal.f[BZ_CENTER], cal.f[BZ_INV_SCALE]);
    pv[0] = reach(lo[1], hi[1], cal.f[BR_CENTER], cal.f[BR_INV_SCALE]);
    if (pu[0] > MF_INPUT_MAX || pv[0] > MF_INPUT_MAX) {
        return MF_E_CALIB;
    }
    pu[1] = pu[0];
    pv[1] = pv[0];
    pu[0] = pv[0] = 1.0f;
    for (m = 2; m <= cal.order; ++m) {
        pu[m] = pu[m - 1] * pu[1];
        pv[m] = pv[m - 1] * pv[1];
    }
    /* the Horner rows: row m holds u^i v^j for i = order + 1 - m, j = m - 1 down to 0; Fz's m, then Fr's m */
    for (m = 1; m <= (uint8_t)(cal.order + 1); ++m) {
        for (j = 0; j < m; ++j) {
            float p = pu[cal.order + 1 - m] * pv[m - 1 - j];
            sz += fabsf(c[j]) * p;
            sr += fabsf(c[m + j]) * p;
        }
        c += 2U * m;
    }
    return (sz <= MF_FORCE_MAX_N && sr <= MF_FORCE_MAX_N) ? MF_OK : MF_E_CALIB;
}

int mf_calib_load(void)
{
    uint8_t version = mf_nv_byte(2);
    uint8_t order = mf_nv_byte(3);
    uint16_t len = mf_nv_u16(4);
    uint16_t n = mf_nv_u16(6);
    uint8_t name_len = mf_nv_byte(MF_CAL_IMAGE_AT + 5);
    uint16_t n_coef = (uint16_t)((order + 1U) * (order + 2U) / 2U);
    uint8_t thermal = (uint8_t)(version == MF_CAL_VERSION_THERMAL || version == MF_CAL_VERSION_REFERENCE);
    uint16_t coef_at = (uint16_t)(MF_CAL_COEF_AT + (thermal ? MF_CAL_THERMAL_LEN : 0U)
                                  + (version == MF_CAL_VERSION_REFERENCE ? MF_CAL_REFERENCE_LEN : 0U));
    uint16_t fan_at = (uint16_t)(coef_at + 8U * n_coef);
    uint16_t k;
    cal.status = MF_E_CALIB;
    cal.taxels = 0;
    cal.buses = 0;
    cal.thermal = 0;
    cal.reference = 0;
#if MF_GENERIC
    mf_set.ubrr = MF_FALLBACK_UBRR; /* what the UART starts with, unless a valid record says otherwise */
    mf_set.baud = MF_FALLBACK_BAUD;
#endif
    if (mf_nv_byte(0) == MF_CAL_MAGIC0 && mf_nv_byte(1) == MF_CAL_MAGIC1 && version == MF_CAL_VERSION_ARRAY
        && len <= MF_NV_SIZE && len >= MF_CAL_ADDR_AT + 3U && name_len <= MF_CAL_NAME_MAX) {
        return load_array(len, name_len);
    }
    if (mf_nv_byte(0) != MF_CAL_MAGIC0 || mf_nv_byte(1) != MF_CAL_MAGIC1
        || (version != MF_CAL_VERSION && !thermal)
        || order > MF_CAL_MAX_ORDER || n < 3 || n > 200 || len > MF_NV_SIZE || name_len > MF_CAL_NAME_MAX
        || len != (uint16_t)(fan_at + 20U * n + name_len + 2U)
        || record_crc((uint16_t)(len - 2)) != mf_nv_u16((uint16_t)(len - 2))) {
        return MF_E_CALIB;
    }
    if (record_settings() != MF_OK) {
        return MF_E_CALIB;
    }
    for (k = 0; k < N_FLOATS; ++k) {
        cal.f[k] = mf_nv_float((uint16_t)(MF_CAL_FLOATS_AT + 4U * k));
    }
    for (k = 0; k < 2U * n_coef; ++k) {
        cal.coef[k] = mf_nv_float((uint16_t)(coef_at + 4U * k));
    }
    if (version == MF_CAL_VERSION_REFERENCE) {
        uint8_t addr = mf_nv_byte(MF_CAL_COEF_AT + MF_CAL_THERMAL_LEN);
        uint8_t shift = mf_nv_byte(MF_CAL_COEF_AT + MF_CAL_THERMAL_LEN + 1U);
        if (addr < 0x08U || addr > 0x77U || addr == mf_nv_byte(MF_CAL_IMAGE_AT) || shift < 1U || shift > 8U) {
            return MF_E_CALIB;
        }
        cal.reference = addr;
        cal.reference_shift = shift;
    }
    if (thermal) {
        cal.t0_C = mf_nv_float(MF_CAL_COEF_AT);
        for (k = 0; k < 3U; ++k) {
            cal.a_per_C[k] = mf_nv_float((uint16_t)(MF_CAL_COEF_AT + 4U + 4U * k));
        }
        cal.thermal = 1;
    }
    cal.order = order;
    cal.hull_n = n;
    cal.fan_at = fan_at;
    cal.edge_at = (uint16_t)(fan_at + 8U * n);
    cal.name_at = (uint16_t)(cal.edge_at + 12U * n);
    cal.name_len = name_len;
    if (record_bounded() != MF_OK) {
        return MF_E_CALIB;
    }
    cal.status = MF_OK;
    return MF_OK;
}

int mf_calib_status(void)
{
    return cal.status;
}

uint8_t mf_calib_reference(void)
{
    return cal.status == MF_OK ? cal.reference : 0U;
}

uint8_t mf_calib_reference_shift(void)
{
    return cal.reference_shift;
}

uint8_t mf_calib_taxels(void)
{
    return cal.status == MF_OK ? cal.taxels : 0U;
}

uint8_t mf_calib_address(uint8_t k)
{
    return mf_nv_byte((uint16_t)(MF_CAL_ADDR_AT + k));
}

uint8_t mf_calib_bus(uint8_t k)
{
    return (uint8_t)((cal.buses >> k) & 1U);
}

char mf_calib_sha(uint8_t k)
{
    return cal.status == MF_OK ? (char)mf_nv_byte((uint16_t)(MF_CAL_SHA_AT + k)) : '0';
}

uint8_t mf_calib_setting(uint8_t k)
{
    return cal.status == MF_OK ? mf_nv_byte((uint16_t)(MF_CAL_SETTINGS_AT + k)) : 0U;
}

uint8_t mf_calib_name_len(void)
{
    return cal.status == MF_OK ? cal.name_len : 0U;
}

char mf_calib_name(uint8_t k)
{
    return (char)mf_nv_byte((uint16_t)(cal.name_at + k));
}


/* Left of p_0 -> p_k (q relative to p_0), > 0; on it, 0. */
static float fan_side(uint16_t k, float qz, float qr)
{
    return FAN_Z(k) * qr - FAN_R(k) * qz;
}

uint8_t mf_calib_inside(float bz, float br)
{
    float qz, qr;
    uint16_t lo, hi, e;
    if (!(bz >= cal.f[BZ_LO] && bz <= cal.f[BZ_HI] && br >= cal.f[BR_LO] && br <= cal.f[BR_HI])) {
        return 0; /* outside the box, or NaN */
    }
    if (bz >= cal.f[IN_BZ_LO] && bz <= cal.f[IN_BZ_HI] && br >= cal.f[IN_BR_LO] && br <= cal.f[IN_BR_HI]) {
        return 1;
    }
    /* Convex hull: find the fan wedge (p_0, p_k, p_k+1) holding q by bisection, then test its outer edge.
     * O(log N) products, so a long hull costs little more than a short one. */
    qz = bz - cal.f[P0_BZ];
    qr = br - cal.f[P0_BR];
    if (fan_side(1, qz, qr) < 0.0f || fan_side((uint16_t)(cal.hull_n - 1), qz, qr) > 0.0f) {
        return 0;
    }
    lo = 1;
    hi = (uint16_t)(cal.hull_n - 1);
    while ((uint16_t)(hi - lo) > 1U) {
        uint16_t mid = (uint16_t)((lo + hi) / 2U);
        if (fan_side(mid, qz, qr) >= 0.0f) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    e = (uint16_t)(cal.edge_at + 12U * lo);
    return mf_nv_float(e) * bz + mf_nv_float((uint16_t)(e + 4)) * br >= mf_nv_float((uint16_t)(e + 8)) ? 1 : 0;
}

/* Fz and Fr (before the tare) at the scaled field (u, v): F = p_n(v) u^n + ... + p_0(v), each p_i(v) in Horner
 * form; the record holds, for i = n down to 0, the n - i + 1 coefficients of p_i for Fz, then those for Fr. */
static void poly(float u, float v, float *fz, float *fr)
{
    const float *c = cal.coef;
    float az = 0.0f, ar = 0.0f;
    uint8_t m, k;
    for (m = 1; m <= (uint8_t)(cal.order + 1); ++m) {
        float qz = c[0];
        float qr = c[m];
        for (k = 1; k < m; ++k) {
            qz = qz * v + c[k];
            qr = qr * v + c[m + k];
        }
        az = (m == 1) ? qz : az * u + qz;
        ar = (m == 1) ? qr : ar * u + qr;
        c += 2U * m;
    }
    *fz = az;
    *fr = ar;
}

void mf_calib_forces(mf_sample_t *s)
{
    float bx = s->b_uT[0];
    float by = s->b_uT[1];
    float bz = s->b_uT[2];
    float br;
    if (cal.thermal && s->t_C == s->t_C) { /* the field as at the calibration's temperature: B / (1 + a (T - T0)) */
        float dt = s->t_C - cal.t0_C;
        float dx = 1.0f + cal.a_per_C[0] * dt;
        float dy = 1.0f + cal.a_per_C[1] * dt;
        float dz = 1.0f + cal.a_per_C[2] * dt;
        if (dx >= MF_THERMAL_MIN_DEN && dy >= MF_THERMAL_MIN_DEN && dz >= MF_THERMAL_MIN_DEN) {
            bx /= dx;
            by /= dy;
            bz /= dz;
        } else { /* a temperature outside the chip's range (the record's check holds it there): uncorrected, flagged */
            s->flags |= MF_FLAG_OUTSIDE;
        }
    }
    br = sqrtf(bx * bx + by * by);
    float fz, fr;
    poly((bz - cal.f[BZ_CENTER]) * cal.f[BZ_INV_SCALE], (br - cal.f[BR_CENTER]) * cal.f[BR_INV_SCALE], &fz, &fr);
    fz -= cal.f[TARE_FZ];
    fr -= cal.f[TARE_FR];
    if (br >= cal.f[DIRECTION_MIN] && br > 0.0f) {
        float k = cal.f[SHEAR_SIGN] * fr / br;
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
