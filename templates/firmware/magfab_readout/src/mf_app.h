/* The readout loop: chip start-up and recovery, paced acquisition, calibration, frames, host commands.
 * One call of mf_app_poll() emits exactly one frame (binary or text); with an array's record every chip's reading
 * of one cycle (mf_array.h). With a HAL that reads on the bus's own time (mf_hal_t.i2c_begin) a good sample is held instead
 * and goes out while the next one is on the bus (mf_app_flush): the cycle is then the longer of the read and the
 * arithmetic, not their sum, and each good frame leaves one poll later. An array's chip's good reading is held the
 * same way, its reading sent during the next chip's read (the cycle's last chip's during the next cycle's first read,
 * or before a command's reply). */
#ifndef MF_APP_H
#define MF_APP_H

#include <stdint.h>

#include "mf_errors.h"
#include "mf_hal.h"
#include "mf_sample.h"
#include "mlx90393.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MF_HELD_FORCE 1U /* a single taxel's sample: a force frame */
#define MF_HELD_FIELD 2U /* an array chip's: its reading, in the cycle it was read in (mf_array.h) */

typedef struct mf_app {
    const mf_hal_t *hal;
    mlx_t chip;
    uint8_t text_mode;         /* 0 binary frames, 1 text lines ('b' / 't' from the host) */
    uint8_t seq;               /* sequence number of the next frame */
    uint8_t lost;              /* the last recovery failed: retrying every MF_LOST_RETRY_US */
    uint8_t recovered_pending; /* the chip was reset since the last frame */
    int8_t poll_error;         /* error of the latest sample (MF_OK when it was good) */
    int8_t last_error;         /* latest sample error, kept */
    int8_t start_error;        /* latest failed start-up / recovery attempt, kept */
    uint32_t t0;               /* micros() at mf_app_init: frame time zero */
    uint32_t t_next;           /* earliest micros() for the next read (burst) or start attempt (lost) */
    uint32_t errors;           /* samples that failed */
    uint8_t cmd[24];           /* a multi-byte host command ('w', 'r') being received */
    uint8_t cmd_len;
    uint32_t cmd_t;            /* micros() at its first byte: a command not complete in MF_CMD_TIMEOUT_US is dropped */
    uint32_t recoveries;       /* successful recoveries after a failed sample */
    uint8_t held;              /* a good sample read and not yet sent (a HAL with i2c_begin): MF_HELD_*; its words, read */
    uint8_t held_taxel;        /* time, flags, and an array's taxel and cycle */
    uint8_t held_seq;
    uint8_t held_flags;
    uint32_t held_t;
    mlx_raw_t held_raw;
    uint8_t rm_zyxt;           /* the channels the next RM reads (mf_app_read_measurement): an array's subset, 0 all */
    uint8_t queue_addr;        /* the RM to queue behind the next read (mf_app_queue; 0 channels: none) */
    uint8_t queue_zyxt;
    uint32_t queue_not_before;
    mlx_rm_t rm[2];            /* the RMs on the bus's own time: rm[rm_i] the read's, rm[rm_i ^ 1] the one queued */
    uint8_t rm_i;              /* behind it, which started when chained (when: chain_t): the next read's, or the */
    uint8_t chained;           /* reference chip's (mf_app_take_chained) */
    uint32_t chain_t;
    uint8_t cycle_open;        /* an array's binary cycle frame: its head sent, its last chip's piece and CRC not yet */
    uint16_t cycle_crc;        /* its CRC so far */
    uint32_t cycle_t;          /* its head's time: the first chip's read */
} mf_app_t;

void mf_app_init(mf_app_t *a, const mf_hal_t *hal);
void mf_app_poll(mf_app_t *a);
/* Exit, reset, configure and (burst) start the chip, up to MF_START_TRIES times. Every reply after the NOP that
 * reads out the reset's RS is checked for RS and ERROR, and every register is read back, so a chip that
 * restarts anywhere in the sequence fails the attempt instead of streaming on its power-on settings. */
int mf_app_start_chip(mf_app_t *a);
/* The same for the chip at addr7 (an array's chips, one after another). */
int mf_app_start_at(mf_app_t *a, uint8_t addr7);
/* RM (of the a->rm_zyxt channels) of the chip at a->chip.addr, once more MF_RETRY_US later if the chip rejects it
 * while still in the measuring mode (mode_bit: MLX_ST_BURST or MLX_ST_SM): the conversion ran late (the chip's
 * oscillator is slower than the table), and again every MF_RETRY_US while patience_us has not passed since the first
 * attempt. The rejection after that is an error: a single taxel's reads come on its conversions' grid and wait no
 * longer than one retry (patience 0), so a chip much slower than the table shows as errors; an array chip's read
 * comes when the chips before it are read, however late in its conversion, and may have taken the conversion its next
 * read is scheduled for, so that one waits for up to a conversion. *t_us is when the last attempt started (a first
 * attempt on the bus's own time, a held sample sent meanwhile: the next is due MF_RETRY_US after it started, and
 * *t_us says so); *retried says whether there was more than one. */
int mf_app_read_measurement(mf_app_t *a, mlx_raw_t *raw, uint8_t mode_bit, uint32_t patience_us, uint32_t *t_us,
                            uint8_t *retried);
/* Ask the next mf_app_read_measurement to queue the RM of zyxt at addr7 behind its own (a HAL with i2c_next), to
 * start with no time between them when its reply is good and not before not_before: the bus then runs the two back
 * to back. When it starts (a->chained), the next mf_app_read_measurement is that RM's, at that address (a->chip
 * becomes it, waiting for nothing), or mf_app_take_chained takes it. The request holds for one read. */
void mf_app_queue(mf_app_t *a, uint8_t addr7, uint8_t zyxt, uint32_t not_before);
/* The chained RM's reading, checked as mlx_read_measurement checks it (MF_E_ARG when none started). */
int mf_app_take_chained(mf_app_t *a, mlx_raw_t *raw);
/* A chained RM still on the bus waited for and dropped: before anything else uses the bus. */
void mf_app_settle(mf_app_t *a);
/* Act on every byte the host has sent: 'b' binary, 't' text, 'i' the info line, and the EEPROM commands of
 * docs/bundle.md section 4: 'w' <addr:u16> <n:u8, 1..16> <n bytes> <crc:u16> writes (answered by a W line, the
 * calibration record reloaded), 'r' <addr:u16> <n:u8, 1..32> reads (answered by an R line). */
void mf_app_commands(mf_app_t *a);
/* micros() of the HAL, and a wait until it reaches t (no wait when t has passed). */
uint32_t mf_app_now(const mf_app_t *a);
void mf_app_wait_until(const mf_app_t *a, uint32_t t);
/* Sample processing without the bus: counts -> microtesla -> forces, flags. */
void mf_app_process(const mlx_raw_t *raw, mf_sample_t *s);
/* Encode and send one frame in the current mode, after the held sample's (mf_app_flush). */
void mf_app_emit(mf_app_t *a, const mf_sample_t *s, uint32_t t_us);
/* The held sample, if any, processed and sent: before any other frame, and before an EEPROM write can change the
 * record its forces come from (in the mode the host last asked for). */
void mf_app_flush(mf_app_t *a);
/* An array chip's reading as the current mode needs it: the cycle frame the counts alone (mf_sample_counts), a
 * text line the microtesla too. */
void mf_app_field_sample(const mf_app_t *a, const mlx_raw_t *raw, mf_sample_t *s);
/* An array chip's reading in the current mode, with the cycle's sequence number (not advanced): its piece of the
 * cycle frame (the frame's head before the first chip's, its CRC after the last chip's), or its text line. */
void mf_app_emit_field(mf_app_t *a, uint8_t taxel, const mf_sample_t *s, uint32_t t_us);

#ifdef __cplusplus
}
#endif

#endif
