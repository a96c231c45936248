/* The readout core (magfab_readout/src: mf_app and the MLX90393 driver) on an RP2040 board: its hardware layer
 * (mf_hal.h) from the RP2040 datasheet, for the board the compiler's -D flags name (magfab.export.rp2040):
 *   MF_RP_I2C (0 or 1: the I2C controller), MF_RP_SDA and MF_RP_SCL (its GPIOs, function 3 of table 2.19 in 2.19.2);
 *   with MF_BUSES=2 a second bus on the other controller, MF_RP_SDA_B and MF_RP_SCL_B (an array record's taxels
 *   on it: mf_calib_bus);
 *   MF_NV_FLASH_OFFSET (the record's flash sector: mf_nv.c, flash.c).
 *   TIMER (4.6): micros() is the raw low word of the 1 MHz count (TIMERAWL).
 *   I2C (4.3, the DW_apb_i2c): master, polled, at the record's clock (SCL's period split 3:2 low to high, as the
 *   fast mode's minimum low and high times ask); a transfer's bytes go through IC_DATA_CMD with STOP on
 *   the last and RESTART on the first of a read that follows a write left open; an abort (no ACK) is read from
 *   IC_TX_ABRT_SOURCE, and the STOP the block then sends is waited for (a STOP_DET left set after an abort ended the
 *   next transfer before its time once the bus took time: every recovery after an address NACK failed); every wait
 *   is bounded by the record's I2C timeout. Each chip's bus is its taxel's (mf_calib_bus; bus 0 for any other).
 *   Asynchronous transfers (i2c_begin, i2c_done): a write and a read with a repeated START, queued whole in the
 *   block's 16-entry transmit FIFO, run by the block while the core works; i2c_done collects the reply. A transfer
 *   queued behind it (i2c_next) on the *other* bus starts as soon as its not_before has come, beside the running
 *   one rather than behind it, without waiting for the running reply's checks (the core drops it after a bad
 *   reply: mf_app.c read_rest); one on the same bus is not queued (MF_E_ARG: the core then reads it in turn).
 *   The pins: IO_BANK0 function 3 (I2C), their pads with the input on, the pull-down off and the pull-up on (the
 *   breakout's 2.2 kOhm pull-ups set the bus's rise time; the pads' own keep an unplugged bus high).
 *   The serial link is the USB CDC-ACM device (usb_cdc.c), polled between the core's steps and while a transfer
 *   runs.
 * The clocks come from clocks.c (the crystal, 125 MHz, USB's 48 MHz, the timer's 1 us tick). */
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
#define RESET_I2C_ALL ((1u << 3) | (1u << 4))
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
/* GPIO n's I2C function is controller (n >> 1) & 1's SDA (n even) or SCL (n odd): RP2040 datasheet table 2.19 */
#define MF_RP_PAIR_OK(i2c, sda, scl) (((sda) >> 1 & 1) == (i2c) && ((scl) >> 1 & 1) == (i2c) && !((sda) & 1) && ((scl) & 1))
#if !MF_RP_PAIR_OK(MF_RP_I2C, MF_RP_SDA, MF_RP_SCL)
#error "MF_RP_SDA and MF_RP_SCL must be an SDA and an SCL pin of controller MF_RP_I2C (RP2040 datasheet table 2.19)"
#endif
#if MF_BUSES > 1
#if !defined(MF_RP_SDA_B) || !defined(MF_RP_SCL_B) || !MF_RP_PAIR_OK(1 - MF_RP_I2C, MF_RP_SDA_B, MF_RP_SCL_B)
#error "MF_BUSES=2 needs MF_RP_SDA_B and MF_RP_SCL_B: an SDA and an SCL pin of the other controller"
#endif
#endif

#define I2C_BASE(n) (0x40044000u + 0x4000u * (n))
#define IC_CON 0x00u
#define IC_TAR 0x04u
#define IC_DATA_CMD 0x10u
#define IC_FS_SCL_HCNT 0x1cu
#define IC_FS_SCL_LCNT 0x20u
#define IC_FS_SPKLEN 0xa0u
#define IC_SDA_HOLD 0x7cu
#define IC_RAW_INTR_STAT 0x34u
#define IC_CLR_TX_ABRT 0x54u
#define IC_CLR_STOP_DET 0x60u
#define IC_ENABLE 0x6cu
#define IC_STATUS 0x70u
#define IC_RXFLR 0x78u
#define IC_TX_ABRT_SOURCE 0x80u
#define IC(b, off) REG((b)->base + (off))
#define CMD_READ (1u << 8)
#define CMD_STOP (1u << 9)
#define CMD_RESTART (1u << 10)
#define INTR_TX_ABRT (1u << 6)
#define INTR_STOP_DET (1u << 9)
#define STATUS_TFNF (1u << 1)
#define STATUS_TFE (1u << 2)
#define TX_FIFO 16u /* IC_DATA_CMD's transmit FIFO entries (datasheet 4.3.17: IC_TX_BUFFER_DEPTH 16) */

static uint32_t rp_micros(void *ctx) {
    (void)ctx;
    return REG(TIMERAWL);
}

static void rp_delay_us(void *ctx, uint32_t us) {
    uint32_t start = rp_micros(ctx);
    while ((uint32_t)(rp_micros(ctx) - start) < us) cdc_poll();
}

typedef struct rp_bus {
    uint32_t base;   /* the controller's registers */
    uint8_t open;    /* a write left the bus claimed: the next transfer starts with a repeated START */
    uint32_t hz;     /* the clock the block is set for (0: not yet) */
    uint8_t busy;    /* an asynchronous transfer runs on it: its reply goes to rx */
    uint8_t *rx;
    uint8_t nrx;
    uint8_t got;
    int8_t rc;       /* the last asynchronous transfer's result, once done */
    uint32_t start;  /* micros() at its start */
} rp_bus_t;

static rp_bus_t bus[MF_BUSES];

static uint8_t taxel_at[128]; /* the taxel last found at each address: a guess, checked before it is used */

/* The bus of the chip at addr7: its taxel's (an array record), else the first. The taxel found last time is
 * checked first (the search through the record's addresses cost about 4 us of each read's turnaround on the
 * emulator, a fifth of the bus's rest between reads); a record written since fails the check and is searched. */
static rp_bus_t *bus_of(uint8_t addr7) {
#if MF_BUSES > 1
    uint8_t n = mf_calib_taxels();
    uint8_t k = taxel_at[addr7 & 0x7fu];
    if (k >= n || mf_calib_address(k) != addr7) {
        for (k = 0; k < n && mf_calib_address(k) != addr7; k++) {
        }
        if (k == n) return &bus[0];
        taxel_at[addr7 & 0x7fu] = k;
    }
    return &bus[mf_calib_bus(k)];
#else
    (void)addr7;
    return &bus[0];
#endif
}

/* The block at the record's clock: SCL's period in clk_sys cycles, 3/5 of it low (fast mode: low 1.3 us, high
 * 0.6 us at least), the spike filter a sixteenth of the low time, SDA held 300 ns after SCL falls. */
static void i2c_setup(rp_bus_t *b) {
    uint32_t hz = MF_I2C_HZ == 0u ? 100000u : MF_I2C_HZ;
    uint32_t period = (CLK_SYS_HZ + hz / 2u) / hz;
    uint32_t low = period * 3u / 5u;
    IC(b, IC_ENABLE) = 0u;
    IC(b, IC_CON) = (1u << 0) | (2u << 1) | (1u << 5) | (1u << 6) | (1u << 8); /* master, fast, restart, no slave */
    IC(b, IC_FS_SCL_HCNT) = period - low;
    IC(b, IC_FS_SCL_LCNT) = low;
    IC(b, IC_FS_SPKLEN) = low < 16u ? 1u : low / 16u;
    IC(b, IC_SDA_HOLD) = CLK_SYS_HZ * 3u / 10000000u + 1u;
    IC(b, IC_ENABLE) = 1u;
    b->hz = MF_I2C_HZ;
}

static void i2c_target(rp_bus_t *b, uint8_t addr7) {
    if (b->hz != MF_I2C_HZ) i2c_setup(b); /* an upload changed the record's clock */
    if (IC(b, IC_TAR) != addr7) { /* IC_TAR changes only while the block is off */
        IC(b, IC_ENABLE) = 0u;
        IC(b, IC_TAR) = addr7;
        IC(b, IC_ENABLE) = 1u;
    }
}

/* After an abort (no ACK): the block ends the transfer with a STOP of its own; wait for it (bounded), so that the
 * next transfer's STOP_DET is its own. MF_E_NACK. */
static int i2c_aborted(rp_bus_t *b, uint32_t start) {
    (void)IC(b, IC_TX_ABRT_SOURCE);
    (void)IC(b, IC_CLR_TX_ABRT);
    b->open = 0;
    while (!(IC(b, IC_RAW_INTR_STAT) & INTR_STOP_DET) && (uint32_t)(rp_micros(0) - start) <= MF_I2C_TIMEOUT_US) {
    }
    (void)IC(b, IC_CLR_STOP_DET);
    return MF_E_NACK;
}

/* A transfer past the record's bound: abandoned, the block starts again idle. */
static void i2c_abandon(rp_bus_t *b) {
    IC(b, IC_ENABLE) = 0u;
    IC(b, IC_ENABLE) = 1u;
    b->open = 0;
}

/* The transfer's end: MF_OK, MF_E_NACK after an abort, MF_E_TIMEOUT past the record's bound. */
static int i2c_finish(rp_bus_t *b, uint32_t start, int stop) {
    for (;;) {
        uint32_t raw = IC(b, IC_RAW_INTR_STAT);
        if (raw & INTR_TX_ABRT) return i2c_aborted(b, start);
        if (stop ? (raw & INTR_STOP_DET) != 0u : (IC(b, IC_STATUS) & STATUS_TFE) != 0u) {
            /* an abort empties the transmit FIFO too: TFE seen after the abort bit was read is not a transfer done */
            if (IC(b, IC_RAW_INTR_STAT) & INTR_TX_ABRT) return i2c_aborted(b, start);
            if (stop) (void)IC(b, IC_CLR_STOP_DET);
            return MF_OK;
        }
        if ((uint32_t)(rp_micros(0) - start) > MF_I2C_TIMEOUT_US) {
            i2c_abandon(b);
            return MF_E_TIMEOUT;
        }
    }
}

static void push(rp_bus_t *b, uint32_t cmd) {
    while (!(IC(b, IC_STATUS) & STATUS_TFNF)) {
    }
    IC(b, IC_DATA_CMD) = cmd;
}

static int rp_i2c_write(void *ctx, uint8_t addr7, const uint8_t *data, uint8_t len, uint8_t stop) {
    (void)ctx;
    if (len == 0u) return MF_E_ARG;
    uint32_t start = rp_micros(0);
    rp_bus_t *b = bus_of(addr7);
    i2c_target(b, addr7);
    (void)IC(b, IC_CLR_STOP_DET); /* a STOP_DET from before is not this transfer's */
    for (uint8_t i = 0; i < len; i++) {
        push(b, data[i] | (i == 0u && b->open ? CMD_RESTART : 0u) | (i + 1u == len && stop ? CMD_STOP : 0u));
    }
    int rc = i2c_finish(b, start, stop);
    b->open = (uint8_t)(rc == MF_OK && !stop);
    return rc;
}

/* The reply bytes waiting in the receive FIFO, into b->rx. */
static void drain(rp_bus_t *b) {
    while (b->got < b->nrx && IC(b, IC_RXFLR) != 0u) b->rx[b->got++] = (uint8_t)IC(b, IC_DATA_CMD);
}

/* A read's end once its commands are queued: MF_BUSY while it runs, else as rp_i2c_read's (b->rc). */
static int read_state(rp_bus_t *b) {
    if (!b->busy) return b->rc;
    drain(b);
    uint32_t raw = IC(b, IC_RAW_INTR_STAT);
    if (raw & INTR_TX_ABRT) {
        b->rc = (int8_t)i2c_aborted(b, b->start);
    } else if (b->got == b->nrx && (raw & INTR_STOP_DET)) {
        (void)IC(b, IC_CLR_STOP_DET);
        b->rc = MF_OK;
    } else if ((uint32_t)(rp_micros(0) - b->start) > MF_I2C_TIMEOUT_US) {
        i2c_abandon(b);
        b->rc = (int8_t)(b->got < b->nrx ? MF_E_COUNT : MF_E_TIMEOUT);
    } else {
        return MF_BUSY;
    }
    b->busy = 0;
    return b->rc;
}

/* Queue a transfer whole (ntx bytes written, then nrx read after a repeated START, then STOP: ntx 0 for a read
 * alone) and leave it running on the block. */
static void begin_on(rp_bus_t *b, uint8_t addr7, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx) {
    b->start = rp_micros(0);
    i2c_target(b, addr7);
    (void)IC(b, IC_CLR_STOP_DET);
    for (uint8_t i = 0; i < ntx; i++) push(b, tx[i] | (i == 0u && b->open ? CMD_RESTART : 0u));
    for (uint8_t i = 0; i < nrx; i++) {
        push(b, CMD_READ | (i == 0u && (ntx != 0u || b->open) ? CMD_RESTART : 0u) | (i + 1u == nrx ? CMD_STOP : 0u));
    }
    b->open = 0;
    b->rx = rx;
    b->nrx = nrx;
    b->got = 0;
    b->busy = 1;
}

static int rp_i2c_read(void *ctx, uint8_t addr7, uint8_t *data, uint8_t len) {
    (void)ctx;
    if (len == 0u) return MF_E_ARG;
    rp_bus_t *b = bus_of(addr7);
    int rc;
    if (len > TX_FIFO) return MF_E_ARG;
    begin_on(b, addr7, 0, 0, data, len);
    while ((rc = read_state(b)) == MF_BUSY) {
    }
    return rc;
}

static rp_bus_t *running; /* the asynchronous transfer i2c_done reports */
static struct {
    uint8_t on;      /* a transfer queued on the other bus (i2c_next) */
    uint8_t started; /* and begun */
    rp_bus_t *b;
    uint8_t addr;
    const uint8_t *tx;
    uint8_t ntx;
    uint8_t *rx;
    uint8_t nrx;
    uint32_t not_before;
} queued;

/* The queued transfer begun once its time has come and its bus is free. */
static void service(void) {
    if (queued.on && !queued.started && !queued.b->busy && (int32_t)(rp_micros(0) - queued.not_before) >= 0) {
        begin_on(queued.b, queued.addr, queued.tx, queued.ntx, queued.rx, queued.nrx);
        queued.started = 1;
    }
}

static int rp_i2c_begin(void *ctx, uint8_t addr7, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx) {
    (void)ctx;
    rp_bus_t *b = bus_of(addr7);
    if (ntx == 0u || nrx == 0u || ntx + nrx > TX_FIFO || b->busy) return MF_E_ARG;
    begin_on(b, addr7, tx, ntx, rx, nrx);
    running = b;
    return MF_OK;
}

static int rp_i2c_done(void *ctx) {
    (void)ctx;
    cdc_poll();
    service();
    return running == 0 ? MF_E_ARG : read_state(running);
}

static int rp_i2c_next(void *ctx, uint8_t addr7, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx,
                       uint8_t mask, uint8_t want, uint32_t not_before) {
    (void)ctx;
    (void)mask; /* another bus's transfer does not wait for the running reply (the file's head) */
    (void)want;
    rp_bus_t *b = bus_of(addr7);
    if (running == 0 || b == running || b->busy || queued.on || ntx == 0u || nrx == 0u || ntx + nrx > TX_FIFO
        || (int32_t)(not_before - rp_micros(0)) > (int32_t)MF_CHAIN_AHEAD_US) {
        return MF_E_ARG;
    }
    queued.on = 1;
    queued.started = 0;
    queued.b = b;
    queued.addr = addr7;
    queued.tx = tx;
    queued.ntx = ntx;
    queued.rx = rx;
    queued.nrx = nrx;
    queued.not_before = not_before;
    service();
    return MF_OK;
}

static uint8_t rp_i2c_chained(void *ctx, uint32_t *t_us) {
    (void)ctx;
    service();
    uint8_t started = queued.started;
    if (started) {
        running = queued.b;
        *t_us = running->start;
    }
    queued.on = 0;
    queued.started = 0;
    return started;
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
    0, rp_i2c_write, rp_i2c_read, rp_micros, rp_delay_us, rp_serial_read, rp_serial_write,
    rp_i2c_begin, rp_i2c_done, rp_i2c_next, rp_i2c_chained,
};

/* Pin n as I2C (function 3), its pad with the input on and the pull-up. */
static void i2c_pin(uint32_t n) {
    REG(PADS_GPIO(n)) = PAD_I2C;
    REG(GPIO_CTRL(n)) = FUNC_I2C;
}

static mf_app_t app;

int main(void) {
    (void)clocks_init(); /* a failure leaves the ring oscillator: no USB then, and the host sees no board */
    const uint32_t blocks = RESET_I2C_ALL | RESET_IO_BANK0 | RESET_PADS_BANK0 | RESET_TIMER;
    REG(RESETS_CLR) = blocks;
    while ((REG(RESET_DONE) & blocks) != blocks) {
    }
    bus[0].base = I2C_BASE(MF_RP_I2C);
    i2c_pin(MF_RP_SDA);
    i2c_pin(MF_RP_SCL);
#if MF_BUSES > 1
    bus[1].base = I2C_BASE(1 - MF_RP_I2C);
    i2c_pin(MF_RP_SDA_B);
    i2c_pin(MF_RP_SCL_B);
#endif
    uint8_t id[8];
    mf_flash_unique_id(id); /* the flash chip's unique ID: the USB serial number */
    cdc_serial(id);
    cdc_init();
    (void)mf_calib_load();
    for (uint8_t k = 0; k < MF_BUSES; k++) i2c_setup(&bus[k]);
    mf_app_init(&app, &rp_hal);
    for (;;) {
        cdc_poll();
        mf_app_poll(&app);
    }
}
