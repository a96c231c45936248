/* An array's readout: see mf_array.h. */
#include "mf_array.h"

#include "mf_calib.h"
#include "mf_config.h"

typedef struct mf_taxel {
    uint8_t lost;      /* its last start failed: tried again every MF_LOST_RETRY_US */
    uint8_t recovered; /* started since its last frame */
    int8_t start_rc;   /* the error of its last failed start */
    int8_t sm_rc;      /* single mode: the error of this cycle's SM */
    uint32_t t_ready;  /* the earliest next read: a conversion and the margin after its start or its last read */
    uint32_t t_retry;  /* lost: the next start attempt */
    uint16_t t_raw;    /* its latest temperature word (read one cycle in n, n the chips) */
    uint8_t t_known;   /* t_raw read since its start */
} mf_taxel_t;

static mf_taxel_t taxel[MF_MAX_TAXELS];

/* Reset, configure and (burst) start chip k; MF_OK, else it is lost. The cycle's grid is kept. */
static int start(mf_app_t *a, uint8_t k)
{
    mf_taxel_t *x = &taxel[k];
    uint32_t grid = a->t_next;
    int rc = mf_app_start_at(a, mf_calib_address(k));
    a->t_next = grid;
    if (rc == MF_OK) {
        x->lost = 0;
        x->recovered = 1;
        x->t_known = 0;
        x->t_ready = mf_app_now(a) + (uint32_t)(MF_BURST ? MF_TCONV_US + MF_READ_MARGIN_US : 0UL);
    } else {
        x->lost = 1;
        x->start_rc = (int8_t)rc;
        x->t_retry = mf_app_now(a) + MF_LOST_RETRY_US;
    }
    return rc;
}

void mf_array_start(mf_app_t *a, uint8_t recovered)
{
    uint8_t k;
    for (k = 0; k < mf_calib_taxels(); ++k) {
        if (start(a, k) == MF_OK) {
            taxel[k].recovered = recovered;
        }
    }
    a->lost = 0;
    a->t_next = mf_app_now(a);
}

/* The channels of chip k's RM this cycle: the temperature word (two of the reply's nine bytes) of one chip a cycle,
 * in turn (t_turn), and of a chip just started; the others' field goes out with their latest (a chip's temperature
 * moves over seconds, a cycle is milliseconds); mf_array.h */
static uint8_t channels(uint8_t k, uint8_t t_turn)
{
    uint8_t read_t = (uint8_t)((MF_ZYXT & MLX_T) && (!taxel[k].t_known || t_turn == k));
    return (uint8_t)(read_t ? MF_ZYXT : MF_ZYXT & (uint8_t)~MLX_T);
}

/* RM of chip k (after the SM of this cycle in single mode); *t_us when it was read. In burst mode the next chip's RM
 * is queued behind it (mf_app_queue), so the bus reads the cycle's chips back to back, each from its conversion on. */
static int read_taxel(mf_app_t *a, uint8_t k, uint8_t t_turn, mlx_raw_t *raw, uint32_t *t_us)
{
    uint8_t mode = MF_BURST ? MLX_ST_BURST : MLX_ST_SM;
    uint8_t retried;
    uint8_t read_t;
    uint8_t j = (uint8_t)(k + 1U);
    int rc;
    if (!MF_BURST && taxel[k].sm_rc != MF_OK) {
        *t_us = mf_app_now(a);
        return taxel[k].sm_rc;
    }
    if (!a->chained) { /* else its RM is on the bus already, started behind chip k - 1's */
        mf_app_wait_until(a, taxel[k].t_ready); /* started or read late: a new conversion first */
        a->chip.addr = mf_calib_address(k);
    }
    a->rm_zyxt = channels(k, t_turn);
    read_t = (uint8_t)((a->rm_zyxt & MLX_T) != 0U);
    if (MF_BURST && j < mf_calib_taxels() && !taxel[j].lost) {
        mf_app_queue(a, mf_calib_address(j), channels(j, t_turn), taxel[j].t_ready);
    } else if (MF_BURST && j == mf_calib_taxels() && j > 1U && !taxel[0].lost) {
        /* the next cycle's first chip, from its start (a->t_next, set for it) or its conversion, the later (read
         * this cycle: one chip alone would be queued behind itself before its next conversion is known), with the
         * next cycle's channels (its turn from the sequence number as it will be, wrapping at 256) */
        uint32_t t = (int32_t)(taxel[0].t_ready - a->t_next) > 0 ? taxel[0].t_ready : a->t_next;
        mf_app_queue(a, mf_calib_address(0), channels(0, (uint8_t)((uint8_t)(a->seq + 1U) % j)), t);
    }
    rc = mf_app_read_measurement(a, raw, mode, MF_TCONV_US, t_us, &retried);
    a->rm_zyxt = 0;
    if (rc == MF_OK && read_t) {
        taxel[k].t_raw = raw->t;
        taxel[k].t_known = 1;
    } else if (rc == MF_OK) {
        raw->t = taxel[k].t_raw;
    }
    if (rc == MF_OK && MF_BURST && !(a->chip.status & MLX_ST_BURST)) {
        rc = MF_E_MODE;
    }
    if (rc == MF_OK && MF_BURST) {
        /* its next conversion, whatever the cycle: on the chip's own grid, the scheduled read (or the retry that
         * found a late conversion: the chip's phase) plus whole conversions until past this read. A read on time
         * or late finds the conversion after the last one read, so every read finds a new one and none is skipped
         * that a read could have taken; far behind (a stalled link), the grid starts again from this read. */
        uint32_t next = (retried ? *t_us : taxel[k].t_ready) + MF_TCONV_US;
        if ((int32_t)(*t_us - next) >= (int32_t)((uint32_t)MF_TCONV_US << 3)) { /* 8 conversions (no multiply) */
            next = *t_us + MF_TCONV_US;
        }
        while ((int32_t)(*t_us - next) >= 0) {
            next += MF_TCONV_US;
        }
        taxel[k].t_ready = next;
    }
    return rc;
}

/* Chip k's frame of this cycle: its field, or its fault (then a restart, as a single taxel's chip). */
static void poll_taxel(mf_app_t *a, uint8_t k, uint8_t t_turn)
{
    mf_taxel_t *x = &taxel[k];
    mf_sample_t s;
    mlx_raw_t raw;
    uint32_t t;
    int rc;
    if (x->lost && (int32_t)(mf_app_now(a) - x->t_retry) >= 0 && start(a, k) == MF_OK) {
        ++a->recoveries;
    }
    if (x->lost) {
        mf_sample_fail(&s, x->start_rc, MF_STAGE_START);
        a->start_error = x->start_rc;
        mf_app_emit_field(a, k, &s, mf_app_now(a));
        return;
    }
    rc = read_taxel(a, k, t_turn, &raw, &t);
    if (rc == MF_OK && a->hal->i2c_begin != 0) { /* held: its frame sent while the next chip's read is on the bus */
        a->held_raw = raw;
        a->held_t = t;
        a->held_taxel = k;
        a->held_seq = a->seq;
        a->held_flags = (uint8_t)(x->recovered ? MF_FLAG_RECOVERED : 0U);
        a->held = MF_HELD_FIELD;
        x->recovered = 0;
        return;
    }
    if (rc == MF_OK) {
        mf_app_field_sample(a, &raw, &s);
    } else {
        mf_sample_fail(&s, rc, MF_STAGE_READ);
        a->last_error = (int8_t)rc;
        ++a->errors;
    }
    if (x->recovered) {
        s.flags |= MF_FLAG_RECOVERED;
        x->recovered = 0;
    }
    mf_app_emit_field(a, k, &s, t);
    if (rc != MF_OK && start(a, k) == MF_OK) {
        ++a->recoveries;
    }
}

void mf_array_poll(mf_app_t *a)
{
    uint8_t n = mf_calib_taxels();
    uint8_t k, t_turn;
    if (a->lost) {
        mf_app_settle(a);
        mf_array_start(a, 1); /* a new record was written: every chip with its settings */
    }
    if (MF_BURST) {
        uint32_t now = mf_app_now(a);
        if ((int32_t)(now - a->t_next) > (int32_t)MF_TCONV_US) {
            a->t_next = now; /* behind by more than a conversion (frames or bus slower): no burst of reads */
        }
        if (!a->chained) { /* else the first chip's read started behind the last cycle's, from a->t_next on */
            mf_app_wait_until(a, a->t_next);
        }
        a->t_next += MF_TCONV_US;
    } else {
        for (k = 0; k < n; ++k) { /* the conversions run in parallel */
            if (!taxel[k].lost) {
                a->chip.addr = mf_calib_address(k);
                taxel[k].sm_rc = (int8_t)mlx_command(&a->chip, (uint8_t)(MLX_CMD_SM | MF_ZYXT));
            }
        }
        a->hal->delay_us(a->hal->ctx, MF_TCONV_US + MF_READ_MARGIN_US);
    }
    a->poll_error = MF_OK;
    t_turn = (uint8_t)(a->seq % n);
    for (k = 0; k < n; ++k) {
        poll_taxel(a, k, t_turn);
    }
    /* the cycle's last chip, when held, goes out during the next cycle's first read (or before a command's reply),
     * in this cycle's frame: its head carries this cycle's sequence number */
    a->seq = (uint8_t)(a->seq + 1);
}
