/* A simulated MLX90393 on the host: the I2C command protocol (status byte with mode bits, ERROR, RS and the
 * D1:D0 count; RR/WR register file; SB/SM/RM with conversion timing; EX, RT, NOP, HR, HS), fed with field
 * values in microtesla, with fault injection. Time is a virtual clock in microseconds owned by the caller.
 *
 * Behaviour the datasheet leaves open, as modelled here (the firmware does not rely on any of it for a good
 * sample, only for detecting a bad one):
 *   - RM is rejected (ERROR bit, no data) when no conversion has completed since the last RM or since SB/SM,
 *     or when it asks for a channel the running measurement does not convert;
 *   - RR, WR, SB and SM are rejected outside idle mode; EX always returns to idle;
 *   - SB and SM are rejected for the OSR/DIG_FILT pairs the datasheet forbids with HALLCONF 0xC;
 *   - RS is shown in the first status byte read after a reset (RT or power-on), then cleared. */
#ifndef SIM_MLX90393_H
#define SIM_MLX90393_H

#include <stdint.h>
#include <stdio.h>

#define SIM_IDLE 0
#define SIM_BURST 1
#define SIM_SINGLE 2

enum sim_fault {
    SIM_FAULT_NACK,    /* the next transactions are not acknowledged (count = how many) */
    SIM_FAULT_ERROR,   /* the next commands are rejected with the ERROR bit */
    SIM_FAULT_SHORT,   /* the next RM replies announce (D1:D0) and carry one word fewer */
    SIM_FAULT_TRUNC,   /* the next reads end early: fewer bytes than the master asked for */
    SIM_FAULT_TIMEOUT, /* the next transactions hang the bus until the master's timeout */
    SIM_FAULT_STUCK,   /* conversions stop completing, until RT */
    SIM_FAULT_RESET    /* the chip restarts now (brown-out): registers back to defaults, RS pending */
};

typedef struct sim_mlx {
    uint8_t addr;
    uint16_t reg[32];
    uint8_t mode;
    uint8_t zyxt;           /* channels of the running or last measurement */
    uint8_t rs_pending;
    uint8_t stuck;
    uint8_t single_done;    /* single measurement: converted and not yet read */
    uint64_t t_start;       /* SB / SM time */
    uint64_t burst_read;    /* burst: index of the conversion the last RM returned (0: none yet) */
    double field_uT[3];
    double temperature_C;
    double clock_scale;     /* conversion times x this (the chip's oscillator) */
    const uint64_t *now_us;
    uint8_t reply[16];
    uint8_t reply_len;
    uint8_t have_reply;
    uint16_t fault_count[7];
    uint32_t transactions;
    FILE *log;              /* transaction log, or NULL */
} sim_mlx_t;

void sim_init(sim_mlx_t *s, uint8_t addr7, const uint64_t *now_us);
void sim_power_on(sim_mlx_t *s);
void sim_set_field(sim_mlx_t *s, double bx_uT, double by_uT, double bz_uT, double t_C);
void sim_fault(sim_mlx_t *s, enum sim_fault fault, uint16_t count);
/* One conversion of the zyxt channels with the current registers, microseconds (before clock_scale). */
double sim_conversion_us(const sim_mlx_t *s, uint8_t zyxt);
/* The I2C slave: a write carries a command, the read that follows returns its reply. MF_OK or MF_E_*. */
int sim_i2c_write(sim_mlx_t *s, uint8_t addr7, const uint8_t *data, uint8_t len);
int sim_i2c_read(sim_mlx_t *s, uint8_t addr7, uint8_t *data, uint8_t len);

#endif
