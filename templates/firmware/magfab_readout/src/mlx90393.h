/* Melexis MLX90393 command protocol over I2C (integers only).
 *
 * Every command is one I2C write followed, after a repeated START, by a read whose first byte is the status:
 *   bit 7 BURST_MODE, 6 WOC_MODE, 5 SM_MODE, 4 ERROR, 3 SED (corrected memory error), 2 RS (the chip has
 *   reset; shown once, in the first status byte read after it), 1:0 D: 2 + 2 * D data bytes follow (RR, RM).
 * RM returns the selected channels in the order T, X, Y, Z, each 16 bits big-endian. */
#ifndef MLX90393_H
#define MLX90393_H

#include <stdint.h>

#include "mf_hal.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MLX_CMD_NOP 0x00
#define MLX_CMD_SB 0x10
#define MLX_CMD_SWOC 0x20
#define MLX_CMD_SM 0x30
#define MLX_CMD_RM 0x40
#define MLX_CMD_RR 0x50
#define MLX_CMD_WR 0x60
#define MLX_CMD_EX 0x80
#define MLX_CMD_HR 0xD0
#define MLX_CMD_HS 0xE0
#define MLX_CMD_RT 0xF0

#define MLX_T 0x01
#define MLX_X 0x02
#define MLX_Y 0x04
#define MLX_Z 0x08

#define MLX_ST_BURST 0x80
#define MLX_ST_WOC 0x40
#define MLX_ST_SM 0x20
#define MLX_ST_ERROR 0x10
#define MLX_ST_SED 0x08
#define MLX_ST_RS 0x04
#define MLX_ST_D 0x03

#define MLX_REPLY_MAX 9 /* status + T, X, Y, Z */

typedef struct mlx {
    const mf_hal_t *hal;
    uint8_t addr;   /* 7-bit I2C address */
    uint8_t status; /* status byte of the last reply */
} mlx_t;

/* An RM on the bus's own time (mlx_measurement_begin, mlx_measurement_chain): its chip, channels, command and reply;
 * the HAL writes the reply from its interrupt, so the buffer stays where it is until the RM has ended. */
typedef struct mlx_rm {
    uint8_t addr;
    uint8_t zyxt;
    uint8_t tx;
    uint8_t rx[MLX_REPLY_MAX];
} mlx_rm_t;

typedef struct mlx_raw {
    uint16_t t, x, y, z; /* raw words as the chip sends them; channels not selected are 0 */
} mlx_raw_t;

void mlx_init(mlx_t *m, const mf_hal_t *hal, uint8_t addr7);
/* Channels selected by zyxt bits: the number of 16-bit words RM returns. */
uint8_t mlx_words(uint8_t zyxt);
/* Every reply's status byte is checked, RS before ERROR: MF_E_RESET when the chip shows it restarted (so a
 * reset that strikes any command is seen by the command it strikes), MF_E_CHIP on the ERROR bit. The caller
 * that expects RS (the NOP after RT) accepts MF_E_RESET when chip.status has no ERROR bit. */
/* A one-byte command (SB, SM, EX, RT, NOP, ...): MF_OK, a bus error, MF_E_RESET or MF_E_CHIP. */
int mlx_command(mlx_t *m, uint8_t cmd);
/* RR / WR of a 16-bit register (address 0..31): MF_E_RESET, MF_E_CHIP; RR also checks the byte count (D = 0). */
int mlx_read_register(mlx_t *m, uint8_t reg, uint16_t *value);
int mlx_write_register(mlx_t *m, uint8_t reg, uint16_t value);
/* Read-modify-write of the bits in mask, then read back: MF_E_VERIFY if the chip holds something else. */
int mlx_update_register(mlx_t *m, uint8_t reg, uint16_t mask, uint16_t value);
/* RM of the zyxt channels, checked in this order: RS (MF_E_RESET), ERROR (MF_E_CHIP), D (MF_E_COUNT). */
int mlx_read_measurement(mlx_t *m, uint8_t zyxt, mlx_raw_t *raw);
/* The same RM of m's chip on the bus's own time (the HAL's i2c_begin), in rm: MF_OK once it is under way, MF_E_ARG
 * without channels or an asynchronous HAL; mlx_measurement_end waits for it and checks it as mlx_read_measurement
 * does, m->status its status. */
int mlx_measurement_begin(const mlx_t *m, mlx_rm_t *rm, uint8_t zyxt);
int mlx_measurement_end(mlx_t *m, const mlx_rm_t *rm, mlx_raw_t *raw);
/* next's RM (its addr and zyxt) queued behind running, the RM on the bus (the HAL's i2c_next), to start when
 * running's reply passes every check of mlx_read_measurement for a chip in mode_bit's mode, and not before
 * not_before: MF_OK once queued, MF_E_ARG when the HAL cannot queue it. Once the HAL says it started
 * (mf_hal_t.i2c_chained), mlx_measurement_end(m, next, ...) waits for it. */
int mlx_measurement_chain(const mlx_t *m, mlx_rm_t *next, const mlx_rm_t *running, uint8_t mode_bit,
                          uint32_t not_before);

#ifdef __cplusplus
}
#endif

#endif
