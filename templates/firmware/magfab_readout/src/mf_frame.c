/* Frame and text encoders: see mf_frame.h. */
#include "mf_frame.h"

#include <string.h>

#if defined(__AVR__)
#include <util/crc16.h>
#endif

/* The frame carries IEEE-754 binary32 floats; fails to compile where float is anything else. */
typedef char mf_float_is_32_bits[(sizeof(float) == 4) ? 1 : -1];

uint16_t mf_crc16(const uint8_t *data, uint8_t len)
{
    return mf_crc16_update(0xFFFF, data, len);
}

uint16_t mf_crc16_update(uint16_t crc, const uint8_t *data, uint8_t len)
{
    uint8_t i;
    for (i = 0; i < len; ++i) {
#if defined(__AVR__)
        crc = _crc_xmodem_update(crc, data[i]); /* the same polynomial, unreflected; init is ours */
#else
        uint8_t b;
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (b = 0; b < 8; ++b) {
            crc = (crc & 0x8000U) ? (uint16_t)((crc << 1) ^ 0x1021U) : (uint16_t)(crc << 1);
        }
#endif
    }
    return crc;
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)((v >> 8) & 0xFF);
    p[2] = (uint8_t)((v >> 16) & 0xFF);
    p[3] = (uint8_t)(v >> 24);
}

static void put_f32(uint8_t *p, float x)
{
    uint32_t bits;
    memcpy(&bits, &x, sizeof bits);
    put_u32(p, bits);
}

/* Bytes 0..8 of either frame: sync, type, sequence, flags, time. */
static void put_head(uint8_t *out, uint8_t kind, uint8_t seq, uint32_t t_us, const mf_sample_t *s)
{
    out[0] = MF_FRAME_SYNC0;
    out[1] = MF_FRAME_SYNC1;
    out[2] = kind;
    out[3] = seq;
    out[4] = s->flags;
    put_u32(&out[5], t_us);
}

uint8_t mf_frame_binary(uint8_t *out, uint8_t seq, uint32_t t_us, const mf_sample_t *s)
{
    uint8_t k;
    put_head(out, MF_FRAME_FORCE, seq, t_us, s);
    for (k = 0; k < 3; ++k) {
        put_u16(&out[9 + 2 * k], (uint16_t)s->b_counts[k]);
        put_f32(&out[17 + 4 * k], s->f_N[k]);
    }
    put_u16(&out[15], (s->flags & MF_FLAG_CHIP_ERROR) ? s->fault : s->t_raw); /* an error frame: the fault */
    put_u16(&out[29], mf_crc16(&out[2], 27));
    return MF_FRAME_LEN;
}

uint8_t mf_format_uint(char *out, uint32_t v)
{
    char tmp[10];
    uint8_t n = 0;
    uint8_t k;
    while (v > 0xFFFFU) { /* 32-bit division only for the high digits: it is slow on 8-bit cores */
        tmp[n++] = (char)('0' + (v % 10U));
        v /= 10U;
    }
    {
        uint16_t w = (uint16_t)v;
        do {
            tmp[n++] = (char)('0' + (w % 10U));
            w = (uint16_t)(w / 10U);
        } while (w != 0);
    }
    for (k = 0; k < n; ++k) {
        out[k] = tmp[n - 1 - k];
    }
    return n;
}

static uint8_t put_digits(char *out, uint32_t v, uint8_t width)
{
    uint8_t k;
    uint16_t w;
    for (k = width; k > 4; --k) {
        out[k - 1] = (char)('0' + (v % 10U));
        v /= 10U;
    }
    w = (uint16_t)v;
    for (; k > 0; --k) {
        out[k - 1] = (char)('0' + (w % 10U));
        w = (uint16_t)(w / 10U);
    }
    return width;
}

/* *XXXX: the CRC of the line so far in four upper-case hex digits, as the host checks it. */
static uint8_t put_checksum(char *out, uint8_t n)
{
    static const char hex[] = "0123456789ABCDEF";
    uint16_t crc = mf_crc16((const uint8_t *)out, n);
    uint8_t k;
    out[n++] = '*';
    for (k = 0; k < 4; ++k) {
        out[n++] = hex[(crc >> (12 - 4 * k)) & 0x0FU];
    }
    return n;
}

uint8_t mf_frame_seal(char *out, uint8_t n)
{
    n = put_checksum(out, n);
    out[n++] = '\n';
    return n;
}

static const uint32_t pow10_table[7] = {1UL, 10UL, 100UL, 1000UL, 10000UL, 100000UL, 1000000UL};

uint8_t mf_format_float(char *out, float x, uint8_t decimals)
{
    uint8_t n = 0;
    uint32_t scale;
    uint32_t whole;
    uint32_t frac;
    int8_t exponent = 0;
    if (x != x) {
        memcpy(out, "nan", 3);
        return 3;
    }
    if (x < 0.0f) {
        out[n++] = '-';
        x = -x;
    }
    if (x > 3.4028235e38f) {
        memcpy(&out[n], "inf", 3);
        return (uint8_t)(n + 3);
    }
    if (decimals > 6) {
        decimals = 6;
    }
    if (x >= 1.0e9f) { /* beyond uint32 fixed point: d.dddd e+XX */
        while (x >= 10.0f) {
            x /= 10.0f;
            ++exponent;
        }
    }
    scale = pow10_table[decimals];
    whole = (uint32_t)x;
    frac = (uint32_t)((x - (float)whole) * (float)scale + 0.5f);
    if (frac >= scale) {
        frac -= scale;
        ++whole;
    }
    n = (uint8_t)(n + mf_format_uint(&out[n], whole));
    if (decimals > 0) {
        out[n++] = '.';
        n = (uint8_t)(n + put_digits(&out[n], frac, decimals));
    }
    if (exponent != 0) {
        out[n++] = 'e';
        out[n++] = '+';
        n = (uint8_t)(n + put_digits(&out[n], (uint32_t)exponent, 2));
    }
    return n;
}

/* F,<seq>,... (taxel < 0) or B,<taxel>,<seq>,... without the forces: see mf_frame.h. */
static uint8_t text_line(char *out, int16_t taxel, uint8_t seq, uint32_t t_us, const mf_sample_t *s)
{
    uint8_t n = 0;
    uint8_t k;
    out[n++] = taxel < 0 ? 'F' : 'B';
    if (taxel >= 0) {
        out[n++] = ',';
        n = (uint8_t)(n + mf_format_uint(&out[n], (uint32_t)taxel));
    }
    out[n++] = ',';
    n = (uint8_t)(n + mf_format_uint(&out[n], seq));
    out[n++] = ',';
    n = (uint8_t)(n + mf_format_uint(&out[n], t_us));
    out[n++] = ',';
    n = (uint8_t)(n + mf_format_uint(&out[n], s->flags));
    for (k = 0; taxel < 0 && k < 3; ++k) {
        out[n++] = ',';
        n = (uint8_t)(n + mf_format_float(&out[n], s->f_N[k], 4));
    }
    for (k = 0; k < 3; ++k) {
        out[n++] = ',';
        n = (uint8_t)(n + mf_format_float(&out[n], s->b_uT[k], 2));
    }
    out[n++] = ',';
    n = (uint8_t)(n + mf_format_float(&out[n], s->t_C, 2));
    if (s->flags & MF_FLAG_CHIP_ERROR) {
        out[n++] = ',';
        n = (uint8_t)(n + mf_format_uint(&out[n], s->fault));
    }
    n = put_checksum(out, n);
    out[n++] = '\n';
    return n;
}

uint8_t mf_frame_text(char *out, uint8_t seq, uint32_t t_us, const mf_sample_t *s)
{
    return text_line(out, -1, seq, t_us, s);
}

uint8_t mf_frame_field_text(char *out, uint8_t taxel, uint8_t seq, uint32_t t_us, const mf_sample_t *s)
{
    return text_line(out, taxel, seq, t_us, s);
}

uint8_t mf_frame_cycle_head(uint8_t *out, uint8_t seq, uint32_t t_us, uint8_t chips)
{
    out[0] = MF_FRAME_SYNC0;
    out[1] = MF_FRAME_SYNC1;
    out[2] = MF_FRAME_CYCLE;
    out[3] = seq;
    put_u32(&out[4], t_us);
    out[8] = chips;
    return MF_CYCLE_HEAD_LEN;
}

uint8_t mf_frame_cycle_chip(uint8_t *out, uint32_t dt_us, const mf_sample_t *s)
{
    uint8_t k;
    out[0] = s->flags;
    put_u16(&out[1], dt_us > 0xFFFFUL ? 0xFFFFU : (uint16_t)dt_us);
    for (k = 0; k < 3; ++k) {
        put_u16(&out[3 + 2 * k], (uint16_t)s->b_counts[k]);
    }
    put_u16(&out[9], (s->flags & MF_FLAG_CHIP_ERROR) ? s->fault : s->t_raw);
    return MF_CYCLE_CHIP_LEN;
}

uint8_t mf_frame_cycle_end(uint8_t *out, uint16_t crc)
{
    put_u16(out, crc);
    return 2;
}
