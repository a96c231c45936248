/* Non-volatile storage of the calibration record (docs/bundle.md section 4): the ATmega328P's EEPROM on AVR;
 * on a flash board (MF_NV_FLASH_OFFSET defined: the RP2040 images) two flash sectors, the record's at that offset and
 * the sensor identity's in the sector below it, so that a .uf2 holding a record leaves the identity alone;
 * elsewhere (the host simulator, non-AVR Arduino cores) a RAM copy that starts as this build's record
 * (mf_nv_image.h) and keeps what is written until the next reset. */
#ifndef MF_NV_H
#define MF_NV_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MF_NV_SIZE 1024U
#define MF_NV_IDENTITY 960U /* the sensor identity's bytes: MF_NV_IDENTITY .. MF_NV_SIZE - 1 */

uint8_t mf_nv_byte(uint16_t addr);
uint16_t mf_nv_u16(uint16_t addr); /* little-endian */
uint32_t mf_nv_u32(uint16_t addr); /* little-endian */
float mf_nv_float(uint16_t addr);  /* IEEE-754 binary32, little-endian */
/* Write len bytes from addr on (the caller keeps addr + len within MF_NV_SIZE); bytes already equal are not
 * rewritten (EEPROM wear). Blocks: about 3.4 ms per changed byte on the ATmega328P. */
void mf_nv_write(uint16_t addr, const uint8_t *data, uint8_t len);

#if defined(MF_NV_FLASH_OFFSET)
/* The flash board's part (flash.c): erase the 4 KB sector at flash offset `offset` and program `len` bytes (at most
 * 4096) of `data` into it; the XIP view shows them afterwards. */
void mf_nv_flash_store(uint32_t offset, const uint8_t *data, uint16_t len);
#define MF_NV_SECTOR 4096UL
#endif

#ifdef __cplusplus
}
#endif

#endif
