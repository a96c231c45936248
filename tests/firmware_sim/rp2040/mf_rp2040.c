/* The readout core (magfab_readout/src: mf_app and the MLX90393 driver) on the RP2040, in the harness until the build
 * renders it: its hardware layer (mf_hal.h) from the RP2040 datasheet.
 *   TIMER (4.6): micros() is the raw low word of the 1 MHz count (TIMERAWL).
 *   I2C0 (4.3, the DW_apb_i2c): master, fast mode, polled; a transfer's bytes go through IC_DATA_CMD with STOP on
 *   the last and RESTART on the first of a read that follows a write left open; an abort (no ACK) is read from
 *   IC_TX_ABRT_SOURCE, and the STOP the block then sends is waited for (a STOP_DET left set after an abort ended the
 *   next transfer before its time once the bus took time: every recovery after an address NACK failed); every wait
 *   is bounded by the record's I2C timeout.
 *   The serial link is the USB CDC-ACM device (usb_cdc.c), polled between the core's steps.
 * The clocks come from clocks.c (the crystal, 125 MHz, USB's 48 MHz, the timer's 1 us tick).
 * Not yet here: the pins' function select and pads, the asynchronous transfers (i2c_begin and the rest: 0, so every
 * transfer waits), the flash record. */
#include <stdint.h>

#include "mf_app.h"
#include "mf_calib.h"
#include "mf_config.h"
#include "clocks.h"
#include "mf_errors.h"
#include "usb_cdc.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define RESETS_CLR (0x4000c000u + 0x3000u)
#define RESET_DONE (0x4000c000u + 0x8u)
#define RESET_I2C0 (1u << 3)
#define RESET_TIMER (1u << 21)
#define TIMERAWL (0x40054000u + 0x28u)

#define I2C0 0x40044000u
#define IC_CON (I2C0 + 0x00u)
#define IC_TAR (I2C0 + 0x04u)
#define IC_DATA_CMD (I2C0 + 0x10u)
#define IC_FS_SCL_HCNT (I2C0 + 0x1cu)
#define IC_FS_SCL_LCNT (I2C0 + 0x20u)
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

static void i2c_setup(void) {
    REG(IC_ENABLE) = 0u;
    REG(IC_CON) = (1u << 0) | (2u << 1) | (1u << 5) | (1u << 6) | (1u << 8); /* master, fast, restart, no slave */
    REG(IC_FS_SCL_HCNT) = 125u;  /* 400 kHz at 125 MHz: 1.0 us high, 1.5 us low */
    REG(IC_FS_SCL_LCNT) = 188u;
    REG(IC_ENABLE) = 1u;
}

static void i2c_target(uint8_t addr7) {
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
    REG(RESETS_CLR) = RESET_I2C0 | RESET_TIMER;
    while ((REG(RESET_DONE) & (RESET_I2C0 | RESET_TIMER)) != (RESET_I2C0 | RESET_TIMER)) {
    }
    cdc_init();
    (void)mf_calib_load();
    i2c_setup();
    mf_app_init(&app, &rp_hal);
    for (;;) {
        cdc_poll();
        mf_app_poll(&app);
    }
}
