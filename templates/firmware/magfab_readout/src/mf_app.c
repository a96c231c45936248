/* The readout loop: see mf_app.h. Timing comes from the datasheet's conversion-time table (mf_config.h), never
 * from fixed generous delays: in burst mode the reads follow a fixed grid one conversion apart, the first a small
 * margin after the first conversion is due, so every read finds a fresh conversion and none is skipped (the
 * grid does not drift with the time a read or a frame takes). A read the chip rejects as too early is retried
 * (a single taxel's once, an array chip's for up to a conversion: mf_app_read_measurement), and the grid re-anchors
 * on the retry: the safety net for a chip slower than the table. */
#include "mf_app.h"

#include "mf_array.h"
#include "mf_calib.h"
#include "mf_config.h"
#include "mf_frame.h"
#include "mf_nv.h"
#include "mf_reference.h"

#define MF_CMD_TIMEOUT_US 50000UL
#define MF_READ_MAX 32
#define MF_NO_RECORD_POLL_US 200UL

uint32_t mf_app_now(const mf_app_t *a)
{
    return a->hal->micros(a->hal->ctx);
}

void mf_app_wait_until(const mf_app_t *a, uint32_t t)
{
    int32_t dt = (int32_t)(t - mf_app_now(a));
    if (dt > 0) {
        a->hal->delay_us(a->hal->ctx, (uint32_t)dt);
    }
}

static void send_line(const mf_app_t *a, char *line, uint8_t n)
{
    n = mf_frame_seal(line, n);
    a->hal->serial_write(a->hal->ctx, (const uint8_t *)line, n);
}

static uint8_t put_field(char *out, uint8_t n, uint32_t v)
{
    out[n++] = ',';
    return (uint8_t)(n + mf_format_uint(&out[n], v));
}

/* I,magfab,<name>,<hash>,<gain_sel>,<resolution>,<osr>,<dig_filt>[,<taxels>]: all from the record the image runs now (an
 * empty name, sixteen zeros and zeros without a valid one). */
static void send_info(const mf_app_t *a)
{
    static const char head[] = "I,magfab,";
    char line[MF_TEXT_MAX];
    uint8_t n = 0;
    uint8_t k;
    for (k = 0; head[k] != '\0'; ++k) {
        line[n++] = head[k];
    }
    for (k = 0; k < mf_calib_name_len(); ++k) {
        line[n++] = mf_calib_name(k);
    }
    line[n++] = ',';
    for (k = 0; k < 16; ++k) {
        line[n++] = mf_calib_sha(k);
    }
    for (k = 0; k < 4; ++k) {
        n = put_field(line, n, mf_calib_setting(k));
    }
    if (mf_calib_taxels() > 0) {
        n = put_field(line, n, mf_calib_taxels()); /* an array's: how many chips it reads */
    }
    send_line(a, line, n);
}


/* 'w': W,<addr>,<len>,<rc: 0 written, 1 bad CRC, 2 outside the EEPROM>,<the record now: 0 valid, 10 not> */
static void eeprom_write_command(mf_app_t *a)
{
    char line[40];
    uint16_t addr = (uint16_t)(a->cmd[1] | (uint16_t)a->cmd[2] << 8);
    uint8_t len = a->cmd[3];
    uint16_t crc = (uint16_t)(a->cmd[4 + len] | (uint16_t)a->cmd[5 + len] << 8);
    uint8_t rc = 0;
    uint8_t n;
    if (mf_crc16(a->cmd, (uint8_t)(4 + len)) != crc) {
        rc = 1;
    } else if ((uint32_t)addr + len > MF_NV_SIZE) {
        rc = 2;
    } else {
        mf_app_settle(a); /* the record may change: nothing of the chip's left on the bus */
        mf_app_flush(a); /* the held sample's forces from the record it was read under */
        mf_nv_write(addr, &a->cmd[4], len);
        if (mf_calib_load() == MF_OK) {
            a->lost = 1; /* (re)start the chip now, with the settings of the record just completed */
            a->t_next = mf_app_now(a);
            mf_ref_reset(a); /* and the reference chip, if the record has one */
        }
    }
    line[0] = 'W';
    n = put_field(line, 1, addr);
    n = put_field(line, n, len);
    n = put_field(line, n, rc);
    n = put_field(line, n, (uint32_t)-mf_calib_status());
    send_line(a, line, n);
}

/* 'r': R,<addr>,<bytes in hex> (nothing past the EEPROM's end) */
static void eeprom_read_command(const mf_app_t *a)
{
    static const char hex[] = "0123456789ABCDEF";
    char line[16 + 2 * MF_READ_MAX];
    uint16_t addr = (uint16_t)(a->cmd[1] | (uint16_t)a->cmd[2] << 8);
    uint8_t k, n;
    line[0] = 'R';
    n = put_field(line, 1, addr);
    line[n++] = ',';
    for (k = 0; k < a->cmd[3] && k < MF_READ_MAX && (uint32_t)addr + k < MF_NV_SIZE; ++k) {
        uint8_t b = mf_nv_byte((uint16_t)(addr + k));
        line[n++] = hex[b >> 4];
        line[n++] = hex[b & 0x0F];
    }
    send_line(a, line, n);
}

/* One more byte of a 'w' / 'r' command; runs it when complete. */
static void command_byte(mf_app_t *a, uint8_t c)
{
    uint8_t need;
    a->cmd[a->cmd_len++] = c;
    if (a->cmd_len < 4) {
        return;
    }
    if (a->cmd[0] == 'r') {
        eeprom_read_command(a);
        a->cmd_len = 0;
        return;
    }
    if (a->cmd[3] == 0 || a->cmd[3] > 16) {
        a->cmd_len = 0; /* not a write this firmware makes: dropped */
        return;
    }
    need = (uint8_t)(6 + a->cmd[3]);
    if (a->cmd_len == need) {
        eeprom_write_command(a);
        a->cmd_len = 0;
    }
}

void mf_app_commands(mf_app_t *a)
{
    int c;
    if (a->cmd_len > 0 && (uint32_t)(mf_app_now(a) - a->cmd_t) > MF_CMD_TIMEOUT_US) {
        a->cmd_len = 0; /* the rest never came */
    }
    while ((c = a->hal->serial_read(a->hal->ctx)) >= 0) {
        if (a->cycle_open) {
            mf_app_flush(a); /* an array's cycle frame is finished (its last chip held) before any reply or switch */
        }
        if (a->cmd_len > 0) {
            command_byte(a, (uint8_t)c);
        } else if (c == 'w' || c == 'r') {
            a->cmd_t = mf_app_now(a);
            command_byte(a, (uint8_t)c);
        } else if (c == 'b') {
            a->text_mode = 0;
        } else if (c == 't') {
            a->text_mode = 1;
        } else if (c == 'i') {
            send_info(a);
        }
    }
}

static int start_once(mf_app_t *a)
{
    int rc;
    uint8_t reg;
    (void)mlx_command(&a->chip, MLX_CMD_EX); /* from any mode back to idle; rejected when already idle */
    a->hal->delay_us(a->hal->ctx, MF_EXIT_WAIT_US);
    rc = mlx_command(&a->chip, MLX_CMD_RT);
    if (rc != MF_OK && rc != MF_E_CHIP && rc != MF_E_RESET) {
        return rc; /* the bus failed; the chip's answer to RT is judged by the NOP below, after the reset */
    }
    a->hal->delay_us(a->hal->ctx, MF_RESET_WAIT_US);
    rc = mlx_command(&a->chip, MLX_CMD_NOP); /* reads out (and so clears) the RS bit of the reset */
    if (rc == MF_E_RESET && !(a->chip.status & MLX_ST_ERROR)) {
        rc = MF_OK; /* the RS this sequence expects; from here on any RS fails the start (MF_E_RESET) */
    }
    if (rc != MF_OK) {
        return rc;
    }
    for (reg = 0; reg < 3; ++reg) {
        rc = mlx_update_register(&a->chip, reg, MF_REG_MASK(reg), MF_REG_VALUE(reg));
        if (rc != MF_OK) {
            return rc;
        }
    }
    if (!MF_BURST) {
        a->t_next = mf_app_now(a);
        return MF_OK;
    }
    rc = mlx_command(&a->chip, (uint8_t)(MLX_CMD_SB | MF_ZYXT));
    if (rc == MF_OK && !(a->chip.status & MLX_ST_BURST)) {
        rc = MF_E_MODE;
    }
    if (rc != MF_OK) {
        return rc;
    }
    a->t_next = mf_app_now(a) + MF_TCONV_US + MF_READ_MARGIN_US;
    return MF_OK;
}

int mf_app_start_chip(mf_app_t *a)
{
    return mf_app_start_at(a, MF_I2C_ADDR); /* the record's (a generic image's address can change with an upload) */
}

int mf_app_start_at(mf_app_t *a, uint8_t addr7)
{
    int rc = MF_E_ARG;
    uint8_t attempt;
    a->chip.addr = addr7;
    for (attempt = 0; attempt < MF_START_TRIES; ++attempt) {
        rc = start_once(a);
        if (rc == MF_OK) {
            return MF_OK;
        }
        a->start_error = (int8_t)rc;
    }
    return rc;
}

/* The channels an RM reads: an array's subset, or all the record's. */
#define RM_ZYXT(a) ((a)->rm_zyxt != 0 ? (a)->rm_zyxt : (uint8_t)MF_ZYXT)

void mf_app_queue(mf_app_t *a, uint8_t addr7, uint8_t zyxt, uint32_t not_before)
{
    a->queue_addr = addr7;
    a->queue_zyxt = zyxt;
    a->queue_not_before = not_before;
}

/* The rest of a read on the bus's own time (rm[rm_i], a chip in mode_bit's mode): the RM mf_app_queue asked for queued
 * behind it, the held sample processed and sent meanwhile, then its reply; a->chained when the queued one started. */
static int read_rest(mf_app_t *a, mlx_raw_t *raw, uint8_t mode_bit)
{
    mlx_rm_t *next = &a->rm[a->rm_i ^ 1U];
    uint8_t queued = 0;
    int rc;
    if (a->queue_zyxt != 0U) {
        next->addr = a->queue_addr;
        next->zyxt = a->queue_zyxt;
        queued = (uint8_t)(mlx_measurement_chain(&a->chip, next, &a->rm[a->rm_i], mode_bit,
                                                 a->queue_not_before) == MF_OK);
    }
    mf_app_flush(a);
    rc = mlx_measurement_end(&a->chip, &a->rm[a->rm_i], raw);
    if (queued) {
        a->chained = a->hal->i2c_chained(a->hal->ctx, &a->chain_t);
    }
    if (a->chained && rc != MF_OK) {
        mf_app_settle(a); /* (the HAL chains only behind a good reply: never, but nothing left on the bus) */
    }
    return rc;
}

/* The first RM of a read: with a sample held or one to queue behind it, on the bus's own time (*overlapped = 1);
 * when the RM started behind the read before (a->chained), that one. */
static int read_first(mf_app_t *a, mlx_raw_t *raw, uint8_t mode_bit, uint8_t *overlapped, uint32_t *t_us)
{
    uint8_t zyxt = RM_ZYXT(a);
    if (a->chained) {
        a->rm_i ^= 1U;
        a->chip.addr = a->rm[a->rm_i].addr;
        a->chained = 0;
        *t_us = a->chain_t;
        *overlapped = 1;
        return read_rest(a, raw, mode_bit);
    }
    *t_us = mf_app_now(a);
    *overlapped = (uint8_t)((a->held || a->queue_zyxt)
                            && mlx_measurement_begin(&a->chip, &a->rm[a->rm_i], zyxt) == MF_OK);
    if (*overlapped) {
        return read_rest(a, raw, mode_bit);
    }
    mf_app_flush(a);
    return mlx_read_measurement(&a->chip, zyxt, raw);
}

void mf_app_settle(mf_app_t *a)
{
    mlx_raw_t raw;
    if (a->chained) {
        (void)mf_app_take_chained(a, &raw);
    }
}

int mf_app_take_chained(mf_app_t *a, mlx_raw_t *raw)
{
    if (!a->chained) {
        return MF_E_ARG;
    }
    a->chained = 0;
    a->rm_i ^= 1U;
    a->chip.addr = a->rm[a->rm_i].addr;
    return mlx_measurement_end(&a->chip, &a->rm[a->rm_i], raw);
}

int mf_app_read_measurement(mf_app_t *a, mlx_raw_t *raw, uint8_t mode_bit, uint32_t patience_us, uint32_t *t_us,
                            uint8_t *retried)
{
    int rc;
    uint8_t overlapped;
    *retried = 0;
    rc = read_first(a, raw, mode_bit, &overlapped, t_us);
    if (rc == MF_E_CHIP && (a->chip.status & mode_bit)) {
        /* rejected while still measuring: the conversion is not done yet. Tried again MF_RETRY_US later, and
         * again until patience_us has passed since the first try (mf_app.h) */
        uint32_t first = *t_us;
        *retried = 1;
        do {
            if (overlapped) { /* due MF_RETRY_US after the one before started: the held sample's frame took longer */
                *t_us += MF_RETRY_US;
                mf_app_wait_until(a, *t_us);
            } else {
                a->hal->delay_us(a->hal->ctx, MF_RETRY_US);
                *t_us = mf_app_now(a);
            }
            rc = mlx_read_measurement(&a->chip, RM_ZYXT(a), raw);
        } while (rc == MF_E_CHIP && (a->chip.status & mode_bit) && (uint32_t)(*t_us - first) < patience_us);
    }
    a->queue_zyxt = 0; /* the request held for this read */
    return rc;
}

/* One measurement of the MF_ZYXT channels; *t_us is when it was read. */
static int acquire(mf_app_t *a, mlx_raw_t *raw, uint32_t *t_us)
{
    int rc;
    uint8_t retried;
    if (!MF_BURST) {
        rc = mlx_command(&a->chip, (uint8_t)(MLX_CMD_SM | MF_ZYXT));
        if (rc != MF_OK) {
            *t_us = mf_app_now(a);
            return rc;
        }
        a->hal->delay_us(a->hal->ctx, MF_TCONV_US + MF_READ_MARGIN_US);
        return mf_app_read_measurement(a, raw, MLX_ST_SM, 0, t_us, &retried);
    }
    if ((int32_t)(mf_app_now(a) - a->t_next) > (int32_t)MF_TCONV_US) {
        a->t_next = mf_app_now(a); /* fell behind by more than a conversion (a stalled host link): catch up, not burst */
    }
    mf_app_wait_until(a, a->t_next);
    if (mf_ref_due() != 0U) { /* the reference chip's RM behind this one: read while the sample before is sent */
        mf_app_queue(a, mf_ref_due(), MF_ZYXT, mf_app_now(a));
    }
    rc = mf_app_read_measurement(a, raw, MLX_ST_BURST, 0, t_us, &retried);
    /* the grid: one conversion on from the scheduled read, or from the retry that found a late conversion */
    a->t_next = (retried ? *t_us : a->t_next) + MF_TCONV_US;
    if (rc == MF_OK && !(a->chip.status & MLX_ST_BURST)) {
        rc = MF_E_MODE;
    }
    return rc;
}

void mf_app_process(const mlx_raw_t *raw, mf_sample_t *s)
{
    mf_sample_convert(raw, s);
    mf_ref_apply(s); /* the reference chip's change, before the temperature correction and the calibration */
    mf_calib_forces(s);
}

/* An array chip's piece of the cycle frame: after the frame's head when it is the cycle's first chip, and before
 * the frame's CRC when it is the last. */
static void send_cycle_piece(mf_app_t *a, uint8_t taxel, uint8_t seq, uint8_t flags, const int16_t *counts,
                             uint16_t word, uint32_t t_us)
{
    uint8_t out[MF_CYCLE_HEAD_LEN + MF_CYCLE_CHIP_LEN + 2];
    uint8_t n = 0;
    uint8_t m;
    if (!a->cycle_open) {
        a->cycle_t = t_us;
        n = mf_frame_cycle_head(out, seq, t_us - a->t0, mf_calib_taxels());
        a->cycle_crc = mf_crc16(&out[2], (uint8_t)(n - 2U));
        a->cycle_open = 1;
    }
    m = mf_frame_cycle_chip(&out[n], (int32_t)(t_us - a->cycle_t) > 0 ? t_us - a->cycle_t : 0UL, flags, counts,
                            word);
    a->cycle_crc = mf_crc16_update(a->cycle_crc, &out[n], m);
    n = (uint8_t)(n + m);
    if (taxel + 1U >= mf_calib_taxels()) {
        n = (uint8_t)(n + mf_frame_cycle_end(&out[n], a->cycle_crc));
        a->cycle_open = 0;
    }
    a->hal->serial_write(a->hal->ctx, out, n);
}

/* A force frame (taxel < 0) or an array chip's reading (its text line, or its piece of the cycle frame), in the
 * current mode, with sequence number seq. */
static void send_frame(mf_app_t *a, int16_t taxel, uint8_t seq, const mf_sample_t *s, uint32_t t_us)
{
    if (a->text_mode) {
        char line[MF_TEXT_MAX];
        uint8_t n = taxel < 0 ? mf_frame_text(line, seq, t_us - a->t0, s)
                              : mf_frame_field_text(line, (uint8_t)taxel, seq, t_us - a->t0, s);
        a->hal->serial_write(a->hal->ctx, (const uint8_t *)line, n);
    } else if (taxel >= 0) {
        send_cycle_piece(a, (uint8_t)taxel, seq, s->flags, s->b_counts,
                         (s->flags & MF_FLAG_CHIP_ERROR) ? s->fault : s->t_raw, t_us);
    } else {
        uint8_t frame[MF_FRAME_LEN];
        uint8_t n = mf_frame_binary(frame, seq, t_us - a->t0, s);
        a->hal->serial_write(a->hal->ctx, frame, n);
    }
}

void mf_app_emit(mf_app_t *a, const mf_sample_t *s, uint32_t t_us)
{
    mf_app_flush(a);
    send_frame(a, -1, a->seq, s, t_us);
    a->seq = (uint8_t)(a->seq + 1);
}

void mf_app_field_sample(const mf_app_t *a, const mlx_raw_t *raw, mf_sample_t *s)
{
    if (a->text_mode) {
        mf_sample_convert(raw, s); /* a text line gives microtesla */
    } else {
        mf_sample_counts(raw, s);
    }
}

void mf_app_flush(mf_app_t *a)
{
    mf_sample_t s;
    uint8_t held = a->held;
    if (!held) {
        return;
    }
    a->held = 0;
    if (held == MF_HELD_FIELD && !a->text_mode) { /* its counts straight into its piece: no sample, no float */
        int16_t counts[3];
        uint8_t flags = (uint8_t)(mf_sample_words(&a->held_raw, counts) | a->held_flags);
        send_cycle_piece(a, a->held_taxel, a->held_seq, flags, counts, MF_TEMPERATURE ? a->held_raw.t : 0U,
                         a->held_t);
        return;
    }
    if (held == MF_HELD_FIELD) {
        mf_app_field_sample(a, &a->held_raw, &s);
        s.flags |= a->held_flags;
        send_frame(a, a->held_taxel, a->held_seq, &s, a->held_t);
        return;
    }
    mf_app_process(&a->held_raw, &s);
    s.flags |= a->held_flags;
    mf_app_emit(a, &s, a->held_t);
}

void mf_app_emit_field(mf_app_t *a, uint8_t taxel, const mf_sample_t *s, uint32_t t_us)
{
    mf_app_flush(a);
    send_frame(a, taxel, a->seq, s, t_us);
}

void mf_app_init(mf_app_t *a, const mf_hal_t *hal)
{
    a->hal = hal;
    (void)mf_calib_load(); /* the record: the calibration and (MF_GENERIC) every setting below */
    mlx_init(&a->chip, hal, MF_I2C_ADDR);
    /* without a record, text lines a person reads in any serial monitor; the record's mode applies from the next
     * reset on (the host switches with 'b' / 't' meanwhile) */
    a->text_mode = (uint8_t)(mf_calib_status() != MF_OK || MF_OUTPUT_TEXT ? 1 : 0);
    a->seq = 0;
    a->lost = 0;
    a->recovered_pending = 0;
    a->poll_error = MF_OK;
    a->last_error = MF_OK;
    a->start_error = MF_OK;
    a->errors = 0;
    a->recoveries = 0;
    a->cmd_len = 0;
    a->held = 0;
    a->rm_zyxt = 0;
    a->queue_zyxt = 0;
    a->chained = 0;
    a->rm_i = 0;
    a->cycle_open = 0;
    a->t0 = mf_app_now(a);
    a->t_next = a->t0;
    if (mf_calib_status() != MF_OK) {
        a->lost = 1; /* no record: the chip is left alone (mf_app_poll) until one is written */
    } else if (mf_calib_taxels() > 0) {
        mf_array_start(a, 0);
    } else {
        mf_ref_start(a); /* the reference first: the reads' grid is the sensing chip's */
        if (mf_app_start_chip(a) != MF_OK) {
            a->lost = 1;
            a->t_next = mf_app_now(a);
        }
    }
}

void mf_app_poll(mf_app_t *a)
{
    mf_sample_t s;
    mlx_raw_t raw;
    uint32_t t;
    int rc;
    mf_app_commands(a);
    while (mf_calib_status() != MF_OK && (int32_t)(a->t_next - mf_app_now(a)) > 0) {
        a->hal->delay_us(a->hal->ctx, MF_NO_RECORD_POLL_US); /* the host's commands answered while waiting */
        mf_app_commands(a);
    }
    if (mf_calib_status() != MF_OK) {
        /* no valid record: neither the chip's address nor its settings are known, and no force could be made */
        mf_sample_fail(&s, MF_E_CALIB, MF_STAGE_EEPROM);
        a->poll_error = MF_E_CALIB;
        a->last_error = MF_E_CALIB;
        ++a->errors;
        t = mf_app_now(a);
        mf_app_emit(a, &s, t);
        a->lost = 1; /* started when a valid record is written (mf_app_commands) */
        a->t_next = t + MF_NO_RECORD_US;
        return;
    }
    if (mf_calib_taxels() > 0) {
        mf_array_poll(a); /* an array's record: every chip's reading each cycle, in one cycle frame */
        return;
    }
    if (a->lost) {
        mf_app_wait_until(a, a->t_next);
        rc = mf_app_start_chip(a);
        if (rc != MF_OK) {
            mf_sample_fail(&s, rc, MF_STAGE_START);
            a->poll_error = (int8_t)rc;
            a->last_error = (int8_t)rc;
            ++a->errors;
            t = mf_app_now(a);
            mf_app_emit(a, &s, t);
            a->t_next = t + MF_LOST_RETRY_US;
            return;
        }
        a->lost = 0;
        a->recovered_pending = 1;
        ++a->recoveries;
    }
    rc = acquire(a, &raw, &t);
    if (rc == MF_OK && a->hal->i2c_begin != 0) { /* held: sent while the next sample is on the bus */
        mf_ref_update(a);
        a->held_raw = raw;
        a->held_t = t;
        a->held_flags = (uint8_t)(a->recovered_pending ? MF_FLAG_RECOVERED : 0U);
        a->held = MF_HELD_FORCE;
        a->recovered_pending = 0;
        a->poll_error = MF_OK;
        return;
    }
    if (rc == MF_OK) {
        mf_ref_update(a);
        mf_app_process(&raw, &s);
    } else {
        mf_sample_fail(&s, rc, MF_STAGE_READ);
        a->last_error = (int8_t)rc;
        ++a->errors;
    }
    a->poll_error = (int8_t)rc;
    if (a->recovered_pending) {
        s.flags |= MF_FLAG_RECOVERED;
        a->recovered_pending = 0;
    }
    mf_app_emit(a, &s, t);
    if (rc != MF_OK) {
        if (mf_app_start_chip(a) == MF_OK) {
            a->recovered_pending = 1;
            ++a->recoveries;
        } else {
            a->lost = 1;
            a->t_next = mf_app_now(a) + MF_LOST_RETRY_US;
        }
    }
}
