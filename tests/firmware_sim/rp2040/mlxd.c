/* The build's MLX90393 model (firmware/host/sim_mlx90393.c) served to the RP2040 harness (run.mjs --mlx): one
 * command a line on the request FIFO, one answer a line on the reply FIFO, so that the emulator's I2C callbacks can
 * ask it synchronously. The same model answers the AVR image on simavr (tests/export/simbus/mlxbus.c).
 *   F bx by bz t_C         the field it serves (uT) and its temperature          -> 0
 *   A addr7                whether a chip answers at the address                 -> 1 or 0
 *   W addr7 t_us hex       a write (the command), at the emulator's time t_us    -> rc
 *   R addr7 t_us n         a read of n bytes (the reply)                         -> rc hex
 *   X fault count t_us     a fault inside the chip (enum sim_fault), from now on  -> 0
 * rc is the model's MF_OK or MF_E_*. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim_mlx90393.h"

static uint64_t now_us;

static unsigned hex_bytes(const char *s, uint8_t *out, unsigned cap) {
    unsigned n = 0;
    while (n < cap && s[0] && s[1] && s[0] != '\n') {
        unsigned v;
        if (sscanf(s, "%2x", &v) != 1) break;
        out[n++] = (uint8_t)v;
        s += 2;
    }
    return n;
}

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: mlxd REQUEST_FIFO REPLY_FIFO ADDR7\n");
        return 2;
    }
    FILE *in = fopen(argv[1], "r");
    FILE *out = fopen(argv[2], "w");
    if (!in || !out) return 2;
    sim_mlx_t chip;
    sim_init(&chip, (uint8_t)strtoul(argv[3], 0, 0), &now_us);
    sim_power_on(&chip);
    char line[512];
    while (fgets(line, sizeof line, in)) {
        unsigned addr = 0, n = 0;
        unsigned long long t = 0;
        double bx, by, bz, tc;
        uint8_t buf[64];
        char hex[256];
        if (line[0] == 'F' && sscanf(line + 1, "%lf %lf %lf %lf", &bx, &by, &bz, &tc) == 4) {
            sim_set_field(&chip, bx, by, bz, tc);
            fputs("0\n", out);
        } else if (line[0] == 'X' && sscanf(line + 1, "%u %u %llu", &addr, &n, &t) == 3 && addr <= SIM_FAULT_RESET) {
            now_us = t;
            sim_fault(&chip, (enum sim_fault)addr, (uint16_t)n);
            fputs("0\n", out);
        } else if (line[0] == 'A' && sscanf(line + 1, "%u", &addr) == 1) {
            fprintf(out, "%d\n", addr == chip.addr);
        } else if (line[0] == 'W' && sscanf(line + 1, "%u %llu %255s", &addr, &t, hex) == 3) {
            now_us = t;
            fprintf(out, "%d\n", sim_i2c_write(&chip, (uint8_t)addr, buf, (uint8_t)hex_bytes(hex, buf, sizeof buf)));
        } else if (line[0] == 'R' && sscanf(line + 1, "%u %llu %u", &addr, &t, &n) == 3 && n <= sizeof buf) {
            now_us = t;
            memset(buf, 0xff, sizeof buf);
            int rc = sim_i2c_read(&chip, (uint8_t)addr, buf, (uint8_t)n);
            fprintf(out, "%d ", rc);
            for (unsigned i = 0; i < n; i++) fprintf(out, "%02x", buf[i]);
            fputc('\n', out);
        } else {
            fputs("-99\n", out);
        }
        fflush(out);
    }
    return 0;
}
