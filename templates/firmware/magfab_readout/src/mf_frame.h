/* Serial output (docs/bundle.md section 3): the binary force frame with its CRC, and the text line. */
#ifndef MF_FRAME_H
#define MF_FRAME_H

#include <stdint.h>

#include "mf_sample.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MF_FRAME_LEN 31
#define MF_FRAME_SYNC0 0xA5
#define MF_FRAME_SYNC1 0x5A
#define MF_FRAME_FORCE 0x01
#define MF_FRAME_CYCLE 0x03 /* an array's binary cycle: every chip's counts, one head and one CRC */
#define MF_CYCLE_HEAD_LEN 9
#define MF_CYCLE_CHIP_LEN 11
#define MF_TEXT_MAX 176 /* longest text line, checksum and newline included (166: 7 floats of 19 characters) */

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor). */
uint16_t mf_crc16(const uint8_t *data, uint8_t len);
/* The same CRC continued over more bytes (start with 0xFFFF). */
uint16_t mf_crc16_update(uint16_t crc, const uint8_t *data, uint8_t len);
/* The 31-byte frame, little-endian; on a chip error bytes 15..16 carry the fault word instead of the
 * temperature; returns MF_FRAME_LEN. */
uint8_t mf_frame_binary(uint8_t *out, uint8_t seq, uint32_t t_us, const mf_sample_t *s);
/* F,<seq>,<t_us>,<status>,<Fx_N>,<Fy_N>,<Fz_N>,<Bx_uT>,<By_uT>,<Bz_uT>,<T_C>[,<fault>]*XXXX\n : forces to 4
 * decimals, field and temperature to 2; NaN prints as nan; a chip-error line ends with the fault word (the
 * binary frame's bytes 15..16 on an error frame: MF_STAGE_* << 8 | -MF_E_*); XXXX is mf_crc16 of the bytes before the '*' in upper-case hex.
 * out holds MF_TEXT_MAX bytes; returns the length (no terminator). */
uint8_t mf_frame_text(char *out, uint8_t seq, uint32_t t_us, const mf_sample_t *s);
/* An array's cycle frame (binary mode), sent in pieces as the cycle's chips are read: its head (sync, type 0x03, the
 * cycle's seq, the first chip's read time (uint32), the number of chips), then per chip in taxel order its flags, its
 * read time after the head's (uint16 us, 65535 at most), X, Y, Z counts (int16) and the temperature word (the fault
 * word on a chip error), then the CRC-16 of every byte from the type on (mf_crc16_update over the pieces). The head's
 * bytes: returns MF_CYCLE_HEAD_LEN. */
uint8_t mf_frame_cycle_head(uint8_t *out, uint8_t seq, uint32_t t_us, uint8_t chips);
/* One chip's piece (its flags, counts, and temperature or fault word): returns MF_CYCLE_CHIP_LEN. */
uint8_t mf_frame_cycle_chip(uint8_t *out, uint32_t dt_us, uint8_t flags, const int16_t *counts, uint16_t word);
/* The closing CRC (little-endian): returns 2. */
uint8_t mf_frame_cycle_end(uint8_t *out, uint16_t crc);
/* Its text line: B,<taxel>,<seq>,<t_us>,<status>,<Bx_uT>,<By_uT>,<Bz_uT>,<T_C>[,<fault>]*XXXX\n (as mf_frame_text
 * without the forces); out holds MF_TEXT_MAX bytes. */
uint8_t mf_frame_field_text(char *out, uint8_t taxel, uint8_t seq, uint32_t t_us, const mf_sample_t *s);
/* Ends a text line of n bytes: '*', the CRC of those bytes in four upper-case hex digits, '\n'; returns the
 * new length (out holds n + 6 bytes). */
uint8_t mf_frame_seal(char *out, uint8_t n);
/* v in decimal; returns the length (no terminator). */
uint8_t mf_format_uint(char *out, uint32_t v);
/* x with the given decimals (at most 6), nan / inf / -inf, or d.dddde+XX beyond 1e9; returns the length. */
uint8_t mf_format_float(char *out, float x, uint8_t decimals);

#ifdef __cplusplus
}
#endif

#endif
