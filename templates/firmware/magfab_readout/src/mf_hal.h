/* The hardware the core needs, as function pointers, so that the same core runs on bare-metal AVR, on the
 * Arduino core and in the host simulator. */
#ifndef MF_HAL_H
#define MF_HAL_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* How far ahead of now a chained transfer's not_before may be (mf_hal_t.i2c_next). */
#define MF_CHAIN_AHEAD_US 8000UL

typedef struct mf_hal {
    void *ctx; /* handed back to every function */
    /* Write len bytes to the 7-bit address. stop = 0 leaves the bus claimed so that the next i2c_read
     * starts with a repeated START; on any failure the function releases the bus itself.
     * Returns MF_OK, MF_E_NACK, MF_E_BUS, MF_E_TIMEOUT or MF_E_ARG. */
    int (*i2c_write)(void *ctx, uint8_t addr7, const uint8_t *data, uint8_t len, uint8_t stop);
    /* Read exactly len bytes (ACK all but the last), then STOP. Returns MF_OK, MF_E_NACK, MF_E_BUS,
     * MF_E_TIMEOUT, or MF_E_COUNT when fewer than len bytes arrived. */
    int (*i2c_read)(void *ctx, uint8_t addr7, uint8_t *data, uint8_t len);
    uint32_t (*micros)(void *ctx);               /* microseconds, free running, wraps at 2^32 */
    void (*delay_us)(void *ctx, uint32_t us);    /* busy wait at least us microseconds */
    int (*serial_read)(void *ctx);               /* next byte from the host, or -1 when none is waiting */
    void (*serial_write)(void *ctx, const uint8_t *data, uint8_t len); /* blocks until buffered */
    /* Optional (0: every transfer waits): write ntx bytes, repeated START, read nrx bytes (ACK all but the last),
     * STOP, on the bus's own time, returning at once (MF_OK, or MF_E_ARG for a transfer it cannot make); i2c_done
     * then gives MF_BUSY while it runs, else its result as i2c_write and i2c_read give theirs, its own timeout
     * included. tx and rx stay the caller's, untouched, until i2c_done no longer gives MF_BUSY. */
    int (*i2c_begin)(void *ctx, uint8_t addr7, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx);
    int (*i2c_done)(void *ctx);
    /* Optional (0: every transfer of i2c_begin ends with a STOP): while one runs, queue the next (the same
     * arguments), to start behind it with a repeated START and no time between them, when the running transfer
     * ends well, the first byte it read masked by mask equals want, and micros() has reached not_before by then
     * (at most MF_CHAIN_AHEAD_US ahead: MF_E_ARG beyond). i2c_done gives the running transfer's result; once it
     * gives one, i2c_chained says whether the queued transfer started (1, *t_us when; i2c_done then gives its
     * state) or was dropped (0: nothing is on the bus). */
    int (*i2c_next)(void *ctx, uint8_t addr7, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx,
                    uint8_t mask, uint8_t want, uint32_t not_before);
    uint8_t (*i2c_chained)(void *ctx, uint32_t *t_us);
} mf_hal_t;

#ifdef __cplusplus
}
#endif

#endif
