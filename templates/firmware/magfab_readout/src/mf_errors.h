/* Error codes of the magfab readout core. 0 is success; every failure has its own negative code, and the
 * core never turns one into a force: a sample that met any of them goes out with the chip-error flag and
 * NaN forces (docs/bundle.md, status bit 1). */
#ifndef MF_ERRORS_H
#define MF_ERRORS_H

#define MF_OK 0
#define MF_E_NACK (-1)    /* the chip did not acknowledge its address or a byte */
#define MF_E_BUS (-2)     /* bus error, lost arbitration, or a status byte no chip sends (all 1s) */
#define MF_E_TIMEOUT (-3) /* a transfer did not complete in time (SCL or SDA held, clock stretched too long) */
#define MF_E_CHIP (-4)    /* ERROR bit of the status byte: the chip rejected the command */
#define MF_E_COUNT (-5)   /* wrong byte count: D1:D0 of the status byte, or fewer bytes than asked for */
#define MF_E_RESET (-6)   /* RS bit outside a reset: the chip restarted and lost its settings */
#define MF_E_MODE (-7)    /* the status byte shows the wrong mode (the chip left burst mode) */
#define MF_E_VERIFY (-8)  /* a register read back differs from what was written */
#define MF_E_ARG (-9)     /* a transfer the driver cannot make (too long for the bus driver's buffer) */
#define MF_E_CALIB (-10)  /* no valid calibration record in EEPROM (missing, bad CRC, other chip settings) */
#define MF_BUSY 1         /* a transfer still on the bus (mf_hal_t.i2c_done): never a sample's result */

#endif
