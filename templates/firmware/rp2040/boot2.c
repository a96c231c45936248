/* boot2 for the RP2040 boards (RP2040 datasheet 2.8.1.3, "second stage", and 4.10, the SSI): the first 256 bytes of
 * flash, which the bootrom copies to the top of SRAM (0x20041f00) and runs once their checksum holds. It sets the SSI
 * up so that the XIP window reads the flash with the serial 03h command, which every SPI NOR flash answers (the
 * boards' W25Q16JV, GD25Q64C and the rest alike; slower than quad reads, which a later version may set per board),
 * then starts the image: the vector table after boot2 (0x10000100) as VTOR, its stack pointer and reset handler.
 *
 * Position-independent C (it runs from SRAM, not where it is linked): no data, only register writes and calls the
 * compiler makes PC-relative. Built with -Os into at most 252 bytes; magfab.formats.uf2.seal_boot2 appends the
 * checksum. */
#include <stdint.h>

#define REG(a) (*(volatile uint32_t *)(a))
#define SSI 0x18000000u
#define SSI_CTRLR0 (SSI + 0x00u)
#define SSI_CTRLR1 (SSI + 0x04u)
#define SSI_SSIENR (SSI + 0x08u)
#define SSI_BAUDR (SSI + 0x14u)
#define SSI_SPI_CTRLR0 (SSI + 0xf4u)
#define VTOR 0xe000ed08u
#define IMAGE 0x10000100u

__attribute__((section(".boot2"), used, noreturn)) void boot2(void) {
    REG(SSI_SSIENR) = 0u;                              /* the SSI off while it is set up */
    REG(SSI_BAUDR) = 4u;                               /* SCK = clk_sys / 4 (the ring oscillator at boot) */
    REG(SSI_CTRLR0) = (31u << 16) | (3u << 8);         /* DFS_32: 32-bit frames; TMOD: EEPROM read; SPI_FRF std */
    REG(SSI_CTRLR1) = 0u;                              /* NDF: one frame per XIP access */
    REG(SSI_SPI_CTRLR0) = (0x03u << 24)                /* XIP_CMD: 03h, read */
                          | (2u << 8)                  /* INST_L: an 8-bit instruction */
                          | (6u << 2);                 /* ADDR_L: 24 address bits; TRANS_TYPE 0: all serial */
    REG(SSI_SSIENR) = 1u;
    REG(VTOR) = IMAGE;
    uint32_t sp = *(volatile uint32_t *)IMAGE, pc = *(volatile uint32_t *)(IMAGE + 4u);
    __asm__ volatile("msr msp, %0\n\tbx %1" : : "r"(sp), "r"(pc));
    __builtin_unreachable();
}
