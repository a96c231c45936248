/* MLX90393 command protocol: see mlx90393.h. No floating point here. */
#include "mlx90393.h"

#include "mf_errors.h"

void mlx_init(mlx_t *m, const mf_hal_t *hal, uint8_t addr7)
{
    m->hal = hal;
    m->addr = addr7;
    m->status = 0;
}

uint8_t mlx_words(uint8_t zyxt)
{
    /* the channel bits counted without a loop: every read asks it */
    return (uint8_t)((zyxt & 1U) + ((zyxt >> 1) & 1U) + ((zyxt >> 2) & 1U) + ((zyxt >> 3) & 1U));
}

/* Command out, repeated START, reply in; the reply's first byte is the status. */
static int transfer(mlx_t *m, const uint8_t *tx, uint8_t ntx, uint8_t *rx, uint8_t nrx)
{
    int rc = m->hal->i2c_write(m->hal->ctx, m->addr, tx, ntx, 0);
    if (rc != MF_OK) {
        return rc;
    }
    rc = m->hal->i2c_read(m->hal->ctx, m->addr, rx, nrx);
    if (rc != MF_OK) {
        return rc;
    }
    m->status = rx[0];
    return MF_OK;
}

/* Every reply's status: one no chip sends (two mode bits at once: all 1s from a released bus) is a bus
 * error; then RS (the chip restarted and lost its settings, whatever else it says), then ERROR (rejected). */
static int status_rc(uint8_t status)
{
    uint8_t modes = (uint8_t)(status & (MLX_ST_BURST | MLX_ST_WOC | MLX_ST_SM));
    if (modes & (uint8_t)(modes - 1U)) {
        return MF_E_BUS;
    }
    if (status & MLX_ST_RS) {
        return MF_E_RESET;
    }
    return (status & MLX_ST_ERROR) ? MF_E_CHIP : MF_OK;
}

/* D1:D0 against the words expected: 2 + 2 * D bytes follow the status. */
static int check_count(uint8_t status, uint8_t words)
{
    return ((status & MLX_ST_D) + 1U == words) ? MF_OK : MF_E_COUNT;
}

int mlx_command(mlx_t *m, uint8_t cmd)
{
    uint8_t status;
    int rc = transfer(m, &cmd, 1, &status, 1);
    if (rc != MF_OK) {
        return rc;
    }
    return status_rc(status);
}

int mlx_read_register(mlx_t *m, uint8_t reg, uint16_t *value)
{
    uint8_t tx[2];
    uint8_t rx[3];
    int rc;
    tx[0] = MLX_CMD_RR;
    tx[1] = (uint8_t)((reg & 0x3F) << 2);
    rc = transfer(m, tx, 2, rx, 3);
    if (rc == MF_OK) {
        rc = status_rc(rx[0]);
    }
    if (rc != MF_OK) {
        return rc;
    }
    if (check_count(rx[0], 1) != MF_OK) {
        return MF_E_COUNT;
    }
    *value = (uint16_t)(((uint16_t)rx[1] << 8) | rx[2]);
    return MF_OK;
}

int mlx_write_register(mlx_t *m, uint8_t reg, uint16_t value)
{
    uint8_t tx[4];
    uint8_t status;
    int rc;
    tx[0] = MLX_CMD_WR;
    tx[1] = (uint8_t)(value >> 8);
    tx[2] = (uint8_t)(value & 0xFF);
    tx[3] = (uint8_t)((reg & 0x3F) << 2);
    rc = transfer(m, tx, 4, &status, 1);
    if (rc != MF_OK) {
        return rc;
    }
    return status_rc(status);
}

int mlx_update_register(mlx_t *m, uint8_t reg, uint16_t mask, uint16_t value)
{
    uint16_t old;
    uint16_t want;
    uint16_t back;
    int rc = mlx_read_register(m, reg, &old);
    if (rc != MF_OK) {
        return rc;
    }
    want = (uint16_t)((old & (uint16_t)~mask) | (value & mask));
    rc = mlx_write_register(m, reg, want);
    if (rc != MF_OK) {
        return rc;
    }
    rc = mlx_read_register(m, reg, &back);
    if (rc != MF_OK) {
        return rc;
    }
    return back == want ? MF_OK : MF_E_VERIFY;
}

/* An RM's reply (status, then the zyxt channels' words), checked: RS, ERROR, D. */
static int measurement_reply(const uint8_t *rx, uint8_t zyxt, mlx_raw_t *raw)
{
    const uint8_t *p = &rx[1];
    int rc = status_rc(rx[0]);
    if (rc != MF_OK) {
        return rc;
    }
    if (check_count(rx[0], mlx_words(zyxt)) != MF_OK) {
        return MF_E_COUNT;
    }
    /* the reply's order: T, X, Y, Z, each only if asked (0 if not); written out, as every read comes here */
    raw->t = (zyxt & MLX_T) ? (uint16_t)(((uint16_t)p[0] << 8) | p[1]) : 0U;
    p += (zyxt & MLX_T) ? 2 : 0;
    raw->x = (zyxt & MLX_X) ? (uint16_t)(((uint16_t)p[0] << 8) | p[1]) : 0U;
    p += (zyxt & MLX_X) ? 2 : 0;
    raw->y = (zyxt & MLX_Y) ? (uint16_t)(((uint16_t)p[0] << 8) | p[1]) : 0U;
    p += (zyxt & MLX_Y) ? 2 : 0;
    raw->z = (zyxt & MLX_Z) ? (uint16_t)(((uint16_t)p[0] << 8) | p[1]) : 0U;
    return MF_OK;
}

int mlx_read_measurement(mlx_t *m, uint8_t zyxt, mlx_raw_t *raw)
{
    uint8_t rx[MLX_REPLY_MAX];
    uint8_t cmd = (uint8_t)(MLX_CMD_RM | (zyxt & 0x0F));
    uint8_t n = mlx_words(zyxt);
    int rc;
    if (n == 0) {
        return MF_E_ARG;
    }
    rc = transfer(m, &cmd, 1, rx, (uint8_t)(1 + 2 * n));
    return rc == MF_OK ? measurement_reply(rx, zyxt, raw) : rc;
}

int mlx_measurement_begin(const mlx_t *m, mlx_rm_t *rm, uint8_t zyxt)
{
    uint8_t n = mlx_words(zyxt);
    if (n == 0 || m->hal->i2c_begin == 0 || m->hal->i2c_done == 0) {
        return MF_E_ARG;
    }
    rm->addr = m->addr;
    rm->zyxt = zyxt;
    rm->tx = (uint8_t)(MLX_CMD_RM | (zyxt & 0x0F));
    return m->hal->i2c_begin(m->hal->ctx, rm->addr, &rm->tx, 1, rm->rx, (uint8_t)(1 + 2 * n));
}

int mlx_measurement_chain(const mlx_t *m, mlx_rm_t *next, const mlx_rm_t *running, uint8_t mode_bit,
                          uint32_t not_before)
{
    uint8_t n = mlx_words(next->zyxt);
    uint8_t before = mlx_words(running->zyxt);
    /* the running reply's status: this mode alone, no RS, no ERROR, its words' count (SED, a corrected error, is
     * no fault: status_rc and check_count) */
    uint8_t mask = (uint8_t)(MLX_ST_BURST | MLX_ST_WOC | MLX_ST_SM | MLX_ST_ERROR | MLX_ST_RS | MLX_ST_D);
    if (n == 0 || before == 0 || m->hal->i2c_next == 0 || m->hal->i2c_chained == 0) {
        return MF_E_ARG;
    }
    next->tx = (uint8_t)(MLX_CMD_RM | (next->zyxt & 0x0F));
    return m->hal->i2c_next(m->hal->ctx, next->addr, &next->tx, 1, next->rx, (uint8_t)(1 + 2 * n), mask,
                            (uint8_t)(mode_bit | (uint8_t)(before - 1U)), not_before);
}

int mlx_measurement_end(mlx_t *m, const mlx_rm_t *rm, mlx_raw_t *raw)
{
    int rc;
    while ((rc = m->hal->i2c_done(m->hal->ctx)) == MF_BUSY) {
    }
    if (rc != MF_OK) {
        return rc;
    }
    m->status = rm->rx[0];
    return measurement_reply(rm->rx, rm->zyxt, raw);
}
