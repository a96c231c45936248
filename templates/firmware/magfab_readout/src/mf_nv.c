/* See mf_nv.h. */
#include "mf_nv.h"

#include <string.h>

#if defined(__AVR__)
#include <avr/eeprom.h>

uint8_t mf_nv_byte(uint16_t addr)
{
    return eeprom_read_byte((const uint8_t *)(uintptr_t)addr);
}

float mf_nv_float(uint16_t addr)
{
    return eeprom_read_float((const float *)(uintptr_t)addr); /* avr-gcc: little-endian binary32 */
}

void mf_nv_write(uint16_t addr, const uint8_t *data, uint8_t len)
{
    eeprom_update_block(data, (void *)(uintptr_t)addr, len);
}

#else
#if !defined(MF_NV_FLASH_OFFSET)
#include "mf_nv_image.h"
#endif

static uint8_t nv[MF_NV_SIZE];
static uint8_t nv_ready;

static void nv_init(void)
{
    if (!nv_ready) {
#if defined(MF_NV_FLASH_OFFSET) /* the two sectors through the XIP window (erased flash reads 0xFF) */
        memcpy(nv, (const uint8_t *)(0x10000000UL + MF_NV_FLASH_OFFSET), MF_NV_IDENTITY);
        memcpy(nv + MF_NV_IDENTITY, (const uint8_t *)(0x10000000UL + MF_NV_FLASH_OFFSET - MF_NV_SECTOR),
               MF_NV_SIZE - MF_NV_IDENTITY);
#else
        memset(nv, 0xFF, sizeof nv); /* erased EEPROM reads 0xFF */
        memcpy(nv, mf_nv_image, sizeof mf_nv_image);
#endif
        nv_ready = 1;
    }
}

uint8_t mf_nv_byte(uint16_t addr)
{
    nv_init();
    return addr < MF_NV_SIZE ? nv[addr] : 0xFF;
}

float mf_nv_float(uint16_t addr)
{
    uint8_t b[4];
    uint32_t bits;
    float x;
    uint8_t k;
    for (k = 0; k < 4; ++k) {
        b[k] = mf_nv_byte((uint16_t)(addr + k));
    }
    bits = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    memcpy(&x, &bits, sizeof x);
    return x;
}

void mf_nv_write(uint16_t addr, const uint8_t *data, uint8_t len)
{
    uint8_t k;
#if defined(MF_NV_FLASH_OFFSET)
    uint8_t record = 0, identity = 0;
#endif
    nv_init();
    for (k = 0; k < len && (uint16_t)(addr + k) < MF_NV_SIZE; ++k) {
#if defined(MF_NV_FLASH_OFFSET) /* which sector changes */
        if (nv[addr + k] != data[k]) {
            if ((uint16_t)(addr + k) < MF_NV_IDENTITY) {
                record = 1;
            } else {
                identity = 1;
            }
        }
#endif
        nv[addr + k] = data[k];
    }
#if defined(MF_NV_FLASH_OFFSET) /* bytes already equal cost no erase (flash wear, as the EEPROM's update) */
    if (record) {
        mf_nv_flash_store(MF_NV_FLASH_OFFSET, nv, MF_NV_IDENTITY);
    }
    if (identity) {
        mf_nv_flash_store(MF_NV_FLASH_OFFSET - MF_NV_SECTOR, nv + MF_NV_IDENTITY, MF_NV_SIZE - MF_NV_IDENTITY);
    }
#endif
}
#endif

uint16_t mf_nv_u16(uint16_t addr)
{
    return (uint16_t)(mf_nv_byte(addr) | (uint16_t)mf_nv_byte((uint16_t)(addr + 1)) << 8);
}

uint32_t mf_nv_u32(uint16_t addr)
{
    return (uint32_t)mf_nv_u16(addr) | (uint32_t)mf_nv_u16((uint16_t)(addr + 2)) << 16;
}
