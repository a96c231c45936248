/* The calibration record's flash sectors on an RP2040 board (mf_nv.h's mf_nv_flash_store), from the RP2040
 * datasheet without the bootrom's flash functions (no bootrom call anywhere in the image):
 *   The flash is only reachable through the SSI (4.10), which boot2 left in XIP mode (serial 03h reads). While it is
 *   taken out of XIP to send commands, nothing may be read from flash, code included: the functions below run from
 *   SRAM (.ramfunc, copied there with the initialised data by start.c) and take their data from SRAM.
 *   The SSI is set for 8-bit frames, transmit-and-receive; the chip select is held low by IO_QSPI's output override of
 *   QSPI_SS (2.19.6.2, GPIO_QSPI_SS_CTRL.OUTOVER) for the length of each command, as one frame per byte would
 *   otherwise end the command after each byte.
 *   The commands every SPI NOR flash of these boards answers (the Winbond W25Q16JV datasheet's names): 06h write
 *   enable, 20h sector erase (4 KB), 02h page program (256 bytes), 05h read status register 1, whose bit 0 (BUSY) is
 *   polled until the erase or program ends.
 *   Then the SSI goes back to boot2's XIP settings and the XIP cache is flushed (2.6.3.2, XIP_CTRL FLUSH), so the XIP
 *   window shows the new bytes.
 * The flash chip's unique ID (4Bh) is read the same way once at start-up: the board's USB serial number (flash.h). */
#include <stdint.h>

#include "flash.h"
#include "mf_nv.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define SSI 0x18000000u
#define SSI_CTRLR0 (SSI + 0x00u)
#define SSI_CTRLR1 (SSI + 0x04u)
#define SSI_SSIENR (SSI + 0x08u)
#define SSI_SER (SSI + 0x10u)
#define SSI_SR (SSI + 0x28u)
#define SSI_DR0 (SSI + 0x60u)
#define SSI_SPI_CTRLR0 (SSI + 0xf4u)
#define SR_TFNF (1u << 1)
#define SR_RFNE (1u << 3)
#define QSPI_SS_CTRL (0x40018000u + 0x0cu)
#define SS_NORMAL 0u
#define SS_LOW (2u << 8)
#define SS_HIGH (3u << 8)
#define XIP_FLUSH (0x14000000u + 0x04u)
#define PAGE 256u

#define RAMFUNC __attribute__((section(".ramfunc"), noinline, long_call))

RAMFUNC static uint8_t spi_byte(uint8_t out) {
    while (!(REG(SSI_SR) & SR_TFNF)) {
    }
    REG(SSI_DR0) = out;
    while (!(REG(SSI_SR) & SR_RFNE)) {
    }
    return (uint8_t)REG(SSI_DR0);
}

/* One command: its byte, then (addr >= 0) a 24-bit address, then n bytes of data out; the chip select held low. */
RAMFUNC static void command(uint8_t cmd, int32_t addr, const uint8_t *data, uint32_t n) {
    REG(QSPI_SS_CTRL) = SS_LOW;
    (void)spi_byte(cmd);
    if (addr >= 0) {
        (void)spi_byte((uint8_t)(addr >> 16));
        (void)spi_byte((uint8_t)(addr >> 8));
        (void)spi_byte((uint8_t)addr);
    }
    for (uint32_t k = 0; k < n; k++) (void)spi_byte(data[k]);
    REG(QSPI_SS_CTRL) = SS_HIGH;
}

RAMFUNC static void wait_ready(void) {
    uint8_t status;
    do {
        REG(QSPI_SS_CTRL) = SS_LOW;
        (void)spi_byte(0x05u);
        status = spi_byte(0u);
        REG(QSPI_SS_CTRL) = SS_HIGH;
    } while (status & 1u);
}

/* Out of XIP: 8-bit frames, transmit and receive, standard SPI, the chip select held high between commands. */
RAMFUNC static void out_of_xip(void) {
    REG(SSI_SSIENR) = 0u;
    REG(SSI_CTRLR0) = (7u << 16);
    REG(SSI_SER) = 1u;
    REG(SSI_SSIENR) = 1u;
    REG(QSPI_SS_CTRL) = SS_HIGH;
}

/* Back to boot2's XIP settings (boot2.c), the chip select the SSI's again, the XIP cache flushed. */
RAMFUNC static void xip(void) {
    REG(QSPI_SS_CTRL) = SS_NORMAL;
    REG(SSI_SSIENR) = 0u;
    REG(SSI_CTRLR0) = (31u << 16) | (3u << 8);
    REG(SSI_CTRLR1) = 0u;
    REG(SSI_SPI_CTRLR0) = (0x03u << 24) | (2u << 8) | (6u << 2);
    REG(SSI_SSIENR) = 1u;
    REG(XIP_FLUSH) = 1u;
    (void)REG(XIP_FLUSH); /* the read waits for the flush to end */
}

RAMFUNC static void store(uint32_t offset, const uint8_t *data, uint16_t len) {
    out_of_xip();
    command(0x06u, -1, 0, 0);
    command(0x20u, (int32_t)offset, 0, 0);
    wait_ready();
    for (uint32_t at = 0; at < len; at += PAGE) {
        command(0x06u, -1, 0, 0);
        command(0x02u, (int32_t)(offset + at), data + at, len - at < PAGE ? len - at : PAGE);
        wait_ready();
    }
    xip();
}

/* The flash chip's 64-bit unique ID (4Bh, four dummy bytes, then the ID: the W25Q16JV datasheet's Read Unique ID
 * Number), out of XIP and back as store() does. */
RAMFUNC static void unique_id(uint8_t id[8]) {
    out_of_xip();
    REG(QSPI_SS_CTRL) = SS_LOW;
    (void)spi_byte(0x4bu);
    for (uint32_t k = 0; k < 4u; k++) (void)spi_byte(0u);
    for (uint32_t k = 0; k < 8u; k++) id[k] = spi_byte(0u);
    REG(QSPI_SS_CTRL) = SS_HIGH;
    xip();
}

void mf_flash_unique_id(uint8_t id[8]) {
    unique_id(id);
}

void mf_nv_flash_store(uint32_t offset, const uint8_t *data, uint16_t len) {
    if (offset % MF_NV_SECTOR || len > MF_NV_SECTOR) return;
    store(offset, data, len);
}
