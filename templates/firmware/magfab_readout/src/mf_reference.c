/* The reference chip: see mf_reference.h. */
#include "mf_reference.h"

#include "mf_calib.h"
#include "mf_config.h"

static struct {
    uint8_t on;        /* started and read at least once since */
    uint8_t started;
    uint8_t phase;     /* 1: read it this call */
    uint32_t t_retry;  /* a failed chip: the next restart attempt */
    int32_t base[3];   /* its first reading after a start, counts x 256 */
    int32_t avg[3];    /* the exponential average, counts x 256 (integer: no float code on the AVR) */
} ref;

void mf_ref_start(mf_app_t *a)
{
    uint8_t addr = mf_calib_reference();
    uint8_t sensing = a->chip.addr;
    ref.on = 0;
    ref.started = 0;
    if (addr == 0U) {
        return;
    }
    ref.started = (uint8_t)(mf_app_start_at(a, addr) == MF_OK);
    ref.t_retry = mf_app_now(a) + MF_LOST_RETRY_US;
    ref.phase = 0;
    a->chip.addr = sensing;
}

void mf_ref_reset(const mf_app_t *a)
{
    ref.on = 0;
    ref.started = 0;
    ref.t_retry = mf_app_now(a);
}

uint8_t mf_ref_due(void)
{
    return (uint8_t)(MF_BURST && ref.started && ref.phase == 0U ? mf_calib_reference() : 0U);
}

void mf_ref_update(mf_app_t *a)
{
    mlx_raw_t raw;
    mf_sample_t r;
    uint8_t sensing = a->chip.addr;
    uint8_t i;
    int rc;
    if (mf_calib_reference() == 0U) {
        return;
    }
    if (!ref.started) {
        if ((int32_t)(mf_app_now(a) - ref.t_retry) >= 0) {
            uint32_t grid = a->t_next;
            mf_ref_start(a);
            a->t_next = grid; /* the sensing chip's reads keep their grid */
        }
        return;
    }
    ref.phase ^= 1U;
    a->chip.addr = mf_calib_reference();
    if (ref.phase == 0U) {
        rc = MF_BURST ? MF_OK : mlx_command(&a->chip, (uint8_t)(MLX_CMD_SM | MF_ZYXT));
        a->chip.addr = sensing;
        if (rc != MF_OK) {
            ref.started = 0;
            ref.t_retry = mf_app_now(a) + MF_LOST_RETRY_US;
        }
        return;
    }
    rc = a->chained ? mf_app_take_chained(a, &raw) : mlx_read_measurement(&a->chip, MF_ZYXT, &raw);
    if (rc == MF_OK && MF_BURST && !(a->chip.status & MLX_ST_BURST)) {
        rc = MF_E_MODE;
    }
    a->chip.addr = sensing;
    if (rc != MF_OK) {
        if (rc != MF_E_CHIP) { /* anything but a conversion not yet done: restart it in a while */
            ref.started = 0;
            ref.t_retry = mf_app_now(a) + MF_LOST_RETRY_US;
        }
        return;
    }
    mf_sample_counts(&raw, &r); /* counts are all the average needs */
    for (i = 0; i < 3U; ++i) {
        int32_t c = (int32_t)r.b_counts[i] * (int32_t)256;
        if (!ref.on) {
            ref.base[i] = c;
            ref.avg[i] = c;
        } else { /* avg += (c - avg) / 2^shift, rounded (an arithmetic shift, as avr-gcc and gcc make it) */
            uint8_t shift = mf_calib_reference_shift();
            ref.avg[i] += (c - ref.avg[i] + ((int32_t)1 << (shift - 1U))) >> shift;
        }
    }
    ref.on = 1;
}

void mf_ref_apply(mf_sample_t *s)
{
    uint8_t i;
    if (!ref.on || (s->flags & MF_FLAG_CHIP_ERROR)) {
        return;
    }
    for (i = 0; i < 3U; ++i) {
        int32_t c = (int32_t)s->b_counts[i] - ((ref.avg[i] - ref.base[i] + (int32_t)128) >> 8); /* nearest count */
        c = c > (int32_t)32767 ? (int32_t)32767 : (c < (int32_t)-32768 ? (int32_t)-32768 : c);
        s->b_counts[i] = (int16_t)c;
        s->b_uT[i] = (float)c * (i < 2U ? MF_LSB_XY_UT : MF_LSB_Z_UT);
    }
}
