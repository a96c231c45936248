/* Frame and text encoders: see mf_frame.h. */
#include "mf_frame.h"

#include <string.h>

#if defined(__AVR__)
#include <avr/pgmspace.h>

/* CRC-16/CCITT-FALSE a byte at a time: crc_table[i] is the CRC register after shifting byte i through an empty one
 * (i << 8, eight steps of poly 0x1021), in flash (512 bytes). About 14 cycles a byte against avr-libc's
 * _crc_xmodem_update's 22 and its loop: a cycle frame's CRC runs over 11 bytes a chip. The host build computes it
 * bit by bit; tests/export/test_wire.py holds both to binascii.crc_hqx. */
static const uint16_t crc_table[256] PROGMEM = {
    0x0000, 0x1021, 0x2042, 0x3063, 0x4084, 0x50A5, 0x60C6, 0x70E7,
    0x8108, 0x9129, 0xA14A, 0xB16B, 0xC18C, 0xD1AD, 0xE1CE, 0xF1EF,
    0x1231, 0x0210, 0x3273, 0x2252, 0x52B5, 0x4294, 0x72F7, 0x62D6,
    0x9339, 0x8318, 0xB37B, 0xA35A, 0xD3BD, 0xC39C, 0xF3FF, 0xE3DE,
    0x2462, 0x3443, 0x0420, 0x1401, 0x64E6, 0x74C7, 0x44A4, 0x5485,
    0xA56A, 0xB54B, 0x8528, 0x9509, 0xE5EE, 0xF5CF, 0xC5AC, 0xD58D,
    0x3653, 0x2672, 0x1611, 0x0630, 0x76D7, 0x66F6, 0x5695, 0x46B4,
    0xB75B, 0xA77A, 0x9719, 0x8738, 0xF7DF, 0xE7FE, 0xD79D, 0xC7BC,
    0x48C4, 0x58E5, 0x6886, 0x78A7, 0x0840, 0x1861, 0x2802, 0x3823,
    0xC9CC, 0xD9ED, 0xE98E, 0xF9AF, 0x8948, 0x9969, 0xA90A, 0xB92B,
    0x5AF5, 0x4AD4, 0x7AB7, 0x6A96, 0x1A71, 0x0A50, 0x3A33, 0x2A12,
    0xDBFD, 0xCBDC, 0xFBBF, 0xEB9E, 0x9B79, 0x8B58, 0xBB3B, 0xAB1A,
    0x6CA6, 0x7C87, 0x4CE4, 0x5CC5, 0x2C22, 0x3C03, 0x0C60, 0x1C41,
    0xEDAE, 0xFD8F, 0xCDEC, 0xDDCD, 0xAD2A, 0xBD0B, 0x8D68, 0x9D49,
    0x7E97, 0x6EB6, 0x5ED5, 0x4EF4, 0x3E13, 0x2E32, 0x1E51, 0x0E70,
    0xFF9F, 0xEFBE, 0xDFDD, 0xCFFC, 0xBF1B, 0xAF3A, 0x9F59, 0x8F78,
    0x9188, 0x81A9, 0xB1CA, 0xA1EB, 0xD10C, 0xC12D, 0xF14E, 0xE16F,
    0x1080, 0x00A1, 0x30C2, 0x20E3, 0x5004, 0x4025, 0x7046, 0x6067,
    0x83B9, 0x9398, 0xA3FB, 0xB3DA, 0xC33D, 0xD31C, 0xE37F, 0xF35E,
    0x02B1, 0x1290, 0x22F3, 0x32D2, 0x4235, 0x5214, 0x6277, 0x7256,
    0xB5EA, 0xA5CB, 0x95A8, 0x8589, 0xF56E, 0xE54F, 0xD52C, 0xC50D,
    0x34E2, 0x24C3, 0x14A0, 0x0481, 0x7466, 0x6447, 0x5424, 0x4405,
    0xA7DB, 0xB7FA, 0x8799, 0x97B8, 0xE75F, 0xF77E, 0xC71D, 0xD73C,
    0x26D3, 0x36F2, 0x0691, 0x16B0, 0x6657, 0x7676, 0x4615, 0x5634,
    0xD94C, 0xC96D, 0xF90E, 0xE92F, 0x99C8, 0x89E9, 0xB98A, 0xA9AB,
    0x5844, 0x4865, 0x7806, 0x6827, 0x18C0, 0x08E1, 0x3882, 0x28A3,
    0xCB7D, 0xDB5C, 0xEB3F, 0xFB1E, 0x8BF9, 0x9BD8, 0xABBB, 0xBB9A,
    0x4A75, 0x5A54, 0x6A37, 0x7A16, 0x0AF1, 0x1AD0, 0x2AB3, 0x3A92,
    0xFD2E, 0xED0F, 0xDD6C, 0xCD4D, 0xBDAA, 0xAD8B, 0x9DE8, 0x8DC9,
    0x7C26, 0x6C07, 0x5C64, 0x4C45, 0x3CA2, 0x2C83, 0x1CE0, 0x0CC1,
    0xEF1F, 0xFF3E, 0xCF5D, 0xDF7C, 0xAF9B, 0xBFBA, 0x8FD9, 0x9FF8,
    0x6E17, 0x7E36, 0x4E55, 0x5E74, 0x2E93, 0x3EB2, 0x0ED1, 0x1EF0,
};
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
        crc = (uint16_t)((uint16_t)(crc << 8) ^ pgm_read_word(&crc_table[(uint8_t)(crc >> 8) ^ data[i]]));
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

uint8_t mf_frame_cycle_chip(uint8_t *out, uint32_t dt_us, uint8_t flags, const int16_t *counts, uint16_t word)
{
    uint8_t k;
    out[0] = flags;
    put_u16(&out[1], dt_us > 0xFFFFUL ? 0xFFFFU : (uint16_t)dt_us);
    for (k = 0; k < 3; ++k) {
        put_u16(&out[3 + 2 * k], (uint16_t)counts[k]);
    }
    put_u16(&out[9], word);
    return MF_CYCLE_CHIP_LEN;
}

uint8_t mf_frame_cycle_end(uint8_t *out, uint16_t crc)
{
    put_u16(out, crc);
    return 2;
}
