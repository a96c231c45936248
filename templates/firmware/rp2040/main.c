/* The readout core (magfab_readout/src: mf_app and the MLX90393 driver) on an RP2040 board: its hardware layer
 * (mf_hal.h) from the RP2040 datasheet, for the board the compiler's -D flags name (magfab.export.rp2040):
 *   MF_RP_I2C (0 or 1: the I2C controller), MF_RP_SDA and MF_RP_SCL (its GPIOs, function 3 of table 2.19 in 2.19.2),
 *   MF_NV_FLASH_OFFSET (the record's flash sector: mf_nv.c, flash.c).
 *   TIMER (4.6): micros() is the raw low word of the 1 MHz count (TIMERAWL).
 *   I2C (4.3, the DW_apb_i2c): master, polled, at the record's clock (SCL's period split 3:2 low to high, as the
 *   fast mode's minimum low and high times ask); a transfer's bytes go through IC_DATA_CMD with STOP on
 *   the last and RESTART on the first of a read that follows a write left open; an abort (no ACK) is read from
 *   IC_TX_ABRT_SOURCE, and the STOP the block then sends is waited for (a STOP_DET left set after an abort ended the
 *   next transfer before its time once the bus took time: every recovery after an address NACK failed); every wait
 *   is bounded by the record's I2C timeout.
 *   The pins: IO_BANK0 function 3 (I2C), their pads with the input on, the pull-down off and the pull-up on (the
 *   breakout's 2.2 kOhm pull-ups set the bus's rise time; the pads' own keep an unplugged bus high).
 *   The serial link is the USB CDC-ACM device (usb_cdc.c), polled between the core's steps.
 * The clocks come from clocks.c (the crystal, 125 MHz, USB's 48 MHz, the timer's 1 us tick).
 * Not here: the asynchronous transfers (i2c_begin and the rest: 0, so every transfer waits). */
#include <stdint.h>

#include "mf_app.h"
#include "mf_calib.h"
#include "mf_config.h"
#include "clocks.h"
#include "flash.h"
#include "mf_errors.h"
#include "usb_cdc.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define RESETS_CLR (0x4000c000u + 0x3000u)
#define RESET_DONE (0x4000c000u + 0x8u)
#define RESET_I2C (1u << (3 + MF_RP_I2C))
#define RESET_IO_BANK0 (1u << 5)
#define RESET_PADS_BANK0 (1u << 8)
#define RESET_TIMER (1u << 21)
#define TIMERAWL (0x40054000u + 0x28u)
#define GPIO_CTRL(n) (0x40014000u + 8u * (n) + 4u)
#define PADS_GPIO(n) (0x4001c000u + 4u + 4u * (n))
#define PAD_I2C ((1u << 6) | (1u << 4) | (1u << 3) | (1u << 1)) /* IE, 4 mA, pull-up, Schmitt */
#define FUNC_I2C 3u
#define CLK_SYS_HZ 125000000u

#if !defined(MF_RP_I2C) || !defined(MF_RP_SDA) || !defined(MF_RP_SCL)
#error "the board's I2C controller and pins: -DMF_RP_I2C=, -DMF_RP_SDA=, -DMF_RP_SCL= (magfab.export.rp2040)"
#endif
#if ((MF_RP_SDA >> 1) & 1) != MF_RP_I2C || ((MF_RP_SCL >> 1) & 1) != MF_RP_I2C || (MF_RP_SDA & 1) || !(MF_RP_SCL & 1)
#error "MF_RP_SDA and MF_RP_SCL must be an SDA and an SCL pin of controller MF_RP_I2C (RP2040 datasheet table 2.19)"
#endif

#define I2C0 (0x40044000u + 0x4000u * MF_RP_I2C)
#define IC_CON (I2C0 + 0x00u)
#define IC_TAR (I2C0 + 0x04u)
#define IC_DATA_CMD (I2C0 + 0x10u)
#define IC_FS_SCL_HCNT (I2C0 + 0x1cu)
#define IC_FS_SCL_LCNT (I2C0 + 0x20u)
#define IC_FS_SPKLEN (I2C0 + 0xa0u)
#define IC_SDA_HOLD (I2C0 + 0x7cu)
#define IC_RAW_INTR_STAT (I2C0 + 0x34u)
#define IC_CLR_TX_ABRT (I2C0 + 0x54u)
#define IC_CLR_STOP_DET (I2C0 + 0x60u)
#define IC_ENABLE (I2C0 + 0x6cu)
#define IC_STATUS (I2C0 + 0x70u)
#define IC_RXFLR (I2C0 + 0x78u)
#define IC_TX_ABRT_SOURCE (I2C0 + 0x80u)
#define CMD_READ (1u << 8)
#define CMD_STOP (1u << 9)
#define CMD_RESTART (1u << 10)
#define INTR_TX_ABRT (1u << 6)
#define INTR_STOP_DET (1u << 9)
#define STATUS_TFNF (1u << 1)
#define STATUS_TFE (1u << 2)

static uint32_t rp_micros(void *ctx) {
    (void)ctx;
    return REG(TIMERAWL);
}

static void rp_delay_us(void *ctx, uint32_t us) {
    uint32_t start = rp_micros(ctx);
    while ((uint32_t)(rp_micros(ctx) - start) < us) cdc_poll();
}

static uint8_t i2c_open; /* a write left the bus claimed: the next transfer starts with a repeated START */
static uint32_t i2c_hz; /* the clock the block is set for (0: not yet) */

/* The block at the record's clock: SCL's period in clk_sys cycles, 3/5 of it low (fast mode: low 1.3 us, high
 * 0.6 us at least), the spike filter a sixteenth of the low time, SDA held 300 ns after SCL falls. */
static void i2c_setup(void) {
    uint32_t hz = MF_I2C_HZ == 0u ? 100000u : MF_I2C_HZ;
    uint32_t period = (CLK_SYS_HZ + hz / 2u) / hz;
    uint32_t low = period * 3u / 5u;
    REG(IC_ENABLE) = 0u;
    REG(IC_CON) = (1u << 0) | (2u << 1) | (1u << 5) | (1u << 6) | (1u << 8); /* master, fast, restart, no slave */
    REG(IC_FS_SCL_HCNT) = period - low;
    REG(IC_FS_SCL_LCNT) = low;
    REG(IC_FS_SPKLEN) = low < 16u ? 1u : low / 16u;
    REG(IC_SDA_HOLD) = CLK_SYS_HZ * 3u / 10000000u + 1u;
    REG(IC_ENABLE) = 1u;
    i2c_hz = MF_I2C_HZ;
}

static void i2c_target(uint8_t addr7) {
    if (i2c_hz != MF_I2C_HZ) i2c_setup(); /* an upload changed the record's clock */
    if (REG(IC_TAR) != addr7) { /* IC_TAR changes only while the block is off */
        REG(IC_ENABLE) = 0u;
        REG(IC_TAR) = addr7;
        REG(IC_ENABLE) = 1u;
    }
}

/* After an abort (no ACK): the block ends the transfer with a STOP of its own; wait for it (bounded), so that the
 * next transfer's STOP_DET is its own. MF_E_NACK. */
static int i2c_aborted(uint32_t start) {
    (void)REG(IC_TX_ABRT_SOURCE);
    (void)REG(IC_CLR_TX_ABRT);
    i2c_open = 0;
    while (!(REG(IC_RAW_INTR_STAT) & INTR_STOP_DET) && (uint32_t)(rp_micros(0) - start) <= MF_I2C_TIMEOUT_US) {
    }
    (void)REG(IC_CLR_STOP_DET);
    return MF_E_NACK;
}

/* The transfer's end: MF_OK, MF_E_NACK after an abort, MF_E_TIMEOUT past the record's bound. */
static int i2c_finish(uint32_t start, int stop) {
    for (;;) {
        uint32_t raw = REG(IC_RAW_INTR_STAT);
        if (raw & INTR_TX_ABRT) return i2c_aborted(start);
        if (stop ? (raw & INTR_STOP_DET) != 0u : (REG(IC_STATUS) & STATUS_TFE) != 0u) {
            /* an abort empties the transmit FIFO too: TFE seen after the abort bit was read is not a transfer done */
            if (REG(IC_RAW_INTR_STAT) & INTR_TX_ABRT) return i2c_aborted(start);
            if (stop) (void)REG(IC_CLR_STOP_DET);
            return MF_OK;
        }
        if ((uint32_t)(rp_micros(0) - start) > MF_I2C_TIMEOUT_US) {
            REG(IC_ENABLE) = 0u; /* abandon it; the block starts again idle */
            REG(IC_ENABLE) = 1u;
            i2c_open = 0;
            return MF_E_TIMEOUT;
        }
    }
}

static int rp_i2c_write(void *ctx, uint8_t addr7, const uint8_t *data, uint8_t len, uint8_t stop) {
    (void)ctx;
    if (len == 0u) return MF_E_ARG;
    uint32_t start = rp_micros(0);
    i2c_target(addr7);
    (void)REG(IC_CLR_STOP_DET); /* a STOP_DET from before is not this transfer's */
    for (uint8_t i = 0; i < len; i++) {
        while (!(REG(IC_STATUS) & STATUS_TFNF)) {
        }
        REG(IC_DATA_CMD) = data[i] | (i == 0u && i2c_open ? CMD_RESTART : 0u)
                           | (i + 1u == len && stop ? CMD_STOP : 0u);
    }
    int rc = i2c_finish(start, stop);
    i2c_open = (uint8_t)(rc == MF_OK && !stop);
    return rc;
}

static int rp_i2c_read(void *ctx, uint8_t addr7, uint8_t *data, uint8_t len) {
    (void)ctx;
    if (len == 0u) return MF_E_ARG;
    uint32_t start = rp_micros(0);
    i2c_target(addr7);
    (void)REG(IC_CLR_STOP_DET);
    uint8_t got = 0;
    for (uint8_t i = 0; i < len; i++) {
        while (!(REG(IC_STATUS) & STATUS_TFNF)) {
        }
        REG(IC_DATA_CMD) = CMD_READ | (i == 0u && i2c_open ? CMD_RESTART : 0u) | (i + 1u == len ? CMD_STOP : 0u);
        while (got <= i && REG(IC_RXFLR) != 0u) data[got++] = (uint8_t)REG(IC_DATA_CMD);
    }
    i2c_open = 0;
    for (;;) {
        while (got < len && REG(IC_RXFLR) != 0u) data[got++] = (uint8_t)REG(IC_DATA_CMD);
        uint32_t raw = REG(IC_RAW_INTR_STAT);
        if (raw & INTR_TX_ABRT) return i2c_aborted(start);
        if (got == len && (raw & INTR_STOP_DET)) {
            (void)REG(IC_CLR_STOP_DET);
            return MF_OK;
        }
        if ((uint32_t)(rp_micros(0) - start) > MF_I2C_TIMEOUT_US) {
            REG(IC_ENABLE) = 0u;
            REG(IC_ENABLE) = 1u;
            return got < len ? MF_E_COUNT : MF_E_TIMEOUT;
        }
    }
}

static int rp_serial_read(void *ctx) {
    (void)ctx;
    cdc_poll();
    return cdc_read();
}

static void rp_serial_write(void *ctx, const uint8_t *data, uint8_t len) {
    (void)ctx;
    uint32_t sent = 0;
    while (sent < len) {
        sent += cdc_write(data + sent, len - sent);
        cdc_poll();
    }
}

static const mf_hal_t rp_hal = {
    0, rp_i2c_write, rp_i2c_read, rp_micros, rp_delay_us, rp_serial_read, rp_serial_write, 0, 0, 0, 0,
};

static mf_app_t app;

int main(void) {
    (void)clocks_init(); /* a failure leaves the ring oscillator: no USB then, and the host sees no board */
    const uint32_t blocks = RESET_I2C | RESET_IO_BANK0 | RESET_PADS_BANK0 | RESET_TIMER;
    REG(RESETS_CLR) = blocks;
    while ((REG(RESET_DONE) & blocks) != blocks) {
    }
    REG(PADS_GPIO(MF_RP_SDA)) = PAD_I2C;
    REG(PADS_GPIO(MF_RP_SCL)) = PAD_I2C;
    REG(GPIO_CTRL(MF_RP_SDA)) = FUNC_I2C;
    REG(GPIO_CTRL(MF_RP_SCL)) = FUNC_I2C;
    uint8_t id[8];
    mf_flash_unique_id(id); /* the flash chip's unique ID: the USB serial number */
    cdc_serial(id);
    cdc_init();
    (void)mf_calib_load();
    i2c_setup();
    mf_app_init(&app, &rp_hal);
    for (;;) {
        cdc_poll();
        mf_app_poll(&app);
    }
}
