/* The board's flash chip beyond the record (flash.c): its 64-bit unique ID, which every SPI NOR flash of these boards
 * answers to 4Bh; the image gives it as its USB serial number, so that two boards tell apart. */
#ifndef FLASH_H
#define FLASH_H

#include <stdint.h>

void mf_flash_unique_id(uint8_t id[8]);

#endif
