/* The settings the generic image reads from the EEPROM record (docs/bundle.md section 4), after the header:
 * everything a build-specific image would compile in. magfab computes them from the spec and the chip's recipe
 * (magfab.export.firmware.image_settings), so the image itself needs no table and no division. */
#ifndef MF_SETTINGS_H
#define MF_SETTINGS_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MF_SET_BURST 0x01U       /* flags: burst mode (else one SM per sample) */
#define MF_SET_TEMPERATURE 0x02U /* the T channel is converted and reported */
#define MF_SET_TEXT 0x04U        /* text lines at start-up (else binary frames) */
#define MF_SET_RAW_SIGNED 0x08U  /* RES 0/1: two's complement words */

typedef struct mf_settings {
    uint8_t i2c_address; /* 7-bit */
    uint8_t twbr;        /* TWI bit rate and prescaler bits of the bare-metal image */
    uint8_t twps_bits;
    uint8_t flags;       /* MF_SET_* */
    uint8_t zyxt;        /* axis bits z 8, y 4, x 2, t 1 */
    uint8_t name_len;    /* the spec name's bytes at the record's end */
    uint16_t ubrr;       /* USART0 with U2X, bare metal */
    uint32_t baud;       /* the same for the Arduino core */
    uint32_t i2c_hz;
    uint16_t i2c_timeout_us;
    uint16_t reg_mask[3]; /* registers 0x00..0x02: bits the firmware owns, and their values */
    uint16_t reg_value[3];
    uint32_t tconv_us;   /* the datasheet table's conversion time for the zyxt channels */
    uint32_t read_margin_us;
    uint32_t retry_us;
    uint32_t exit_wait_us;
    uint16_t raw_zero;   /* word at zero field (RES 2/3) */
    uint16_t raw_limit;  /* |counts| at the output limit */
    uint16_t t_raw_25c;
    float lsb_xy_uT;
    float lsb_z_uT;
    float t_c_per_lsb;
} mf_settings_t;

/* Loaded by mf_calib_load() from a valid record; without one only the fallback baud is set. */
extern mf_settings_t mf_set;

#ifdef __cplusplus
}
#endif

#endif
