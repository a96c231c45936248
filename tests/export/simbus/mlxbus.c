/* The shipped ATmega328P image on a simulated I2C bus: Debian's libsimavr (1.6) runs the .hex, and the build's
 * own MLX90393 model (firmware/host/sim_mlx90393.c: status byte, RS, ERROR, register file, conversion timing)
 * answers on TWI byte by byte. Built as a shared library and driven from Python through ctypes (__init__.py).
 *
 * Faults on the bus itself are injected here, per address phase or byte: address NACK, data NACK, all-0xFF
 * replies, a held bus (SCL low for a stated time), the chip off the bus, a chip reset at the n-th address phase.
 * Faults inside the chip (ERROR, short reply, reset now, stuck conversions) go to the model.
 *
 * Two simavr 1.6 bugs are corrected here, never in the firmware:
 *  - TWI: writing TWDR with SLA+W sets the TWI's write latch, so simavr reports 0x28/0x30 (data ACK/NACK)
 *    where the hardware reports 0x18/0x20 (SLA+W ACK/NACK). The status that follows an SLA+W is rewritten
 *    before the firmware sees TWINT (counted: status_fixes; on a fixed simavr it never triggers).
 *  - UART: the byte time is set only when UBRRnL is written (reading U2X as it is then) and always counts a
 *    parity bit; it is recomputed the hardware's way on every write of UCSR0A, UCSR0C and UBRR0L.
 * simavr times I2C at about 9 us per byte (400 kHz takes 22.5 us) and has no clock stretching. bus_real_timing
 * corrects that here, never in the firmware: each TWI step's TWINT is held until the time the step takes on a real
 * bus at the SCL clock the image configures (TWBR, TWPS): 9 SCL periods for an address or data byte with its ACK
 * bit, one for a START, two for a repeated START, and after a STOP the bus-free time before the next START.
 *
 * An array: up to MAX_CHIPS models on the one bus, each at its own address with its own field (bus_add_chip); the
 * per-chip calls (field, faults inside the chip, address NACKs, absent, reset_in, clock, registers) act on the
 * chip bus_target chose (0, the first, by default).
 *
 * A temperature ramp (bus_ramp): the chip's temperature rises at a set rate and the field it serves scales with
 * (1 + alpha (T - T_ref)), updated whenever the firmware reads it. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "avr_eeprom.h"
#include "avr_twi.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_hex.h"

#include "sim_mlx90393.h"

#define TWBR_ADDR 0xB8 /* ATmega328P data-space addresses */
#define TWSR_ADDR 0xB9
#define TWCR_ADDR 0xBC
#define UCSR0A_ADDR 0xC0
#define UCSR0C_ADDR 0xC2
#define UBRR0L_ADDR 0xC4
#define UBRR0H_ADDR 0xC5
#define TW_NO_INFO 0xF8
#define UART_CAP (1u << 20)
#define REPLY_MAX 16
#define MAX_CHIPS 16
#define PROFILE_WORDS 16384 /* the ATmega328P's flash, 16-bit words: the profiler's histogram */

typedef struct bus {
    avr_t *avr;
    avr_irq_t *twi_in;
    avr_irq_t *uart_in;
    avr_uart_t *uart0;
    avr_twi_t *twi0;
    sim_mlx_t chips[MAX_CHIPS];
    uint8_t n_chips;
    uint8_t target;         /* the chip the per-chip calls act on */
    sim_mlx_t *on;          /* the chip of the transaction in flight */
    uint64_t now_us;        /* the model's clock: the AVR's cycles in microseconds, synced before each call */
    /* the transaction in flight */
    uint8_t selected;       /* the address byte the chip ACKed; 0: none */
    uint8_t sla_w_pending;  /* the next status follows an SLA+W (simavr 1.6's 0x28/0x30) */
    uint8_t wbuf[REPLY_MAX];
    uint8_t wlen;
    uint8_t rbuf[REPLY_MAX];
    uint8_t ridx;
    /* faults on the bus */
    uint32_t nack_addr[MAX_CHIPS]; /* the next n address phases for each chip get no ACK */
    uint32_t nack_data;     /* the next n written data bytes get no ACK */
    uint32_t ff_reads;      /* the next n reads are ACKed, then every byte reads 0xFF (SDA released) */
    uint64_t hang_for_us;   /* from the next TWI step on, hold the bus this long */
    uint64_t hang_until_us; /* until then every TWI step is held: TWINT is taken back (SCL held low) */
    uint8_t absent[MAX_CHIPS]; /* each chip off the bus */
    uint32_t reset_in;      /* the target restarts at the start of the n-th address phase from now; 0: never */
    uint8_t reset_chip;
    /* counters */
    uint32_t status_fixes;
    uint32_t phases;        /* address phases seen */
    uint32_t held;          /* TWI steps held */
    uint32_t *pc_hist;      /* profiler: samples per word address */
    uint32_t pc_period;
    uint8_t in_step;        /* a TWI step in flight: the firmware waits on the bus */
    uint32_t bus_samples;   /* profiler samples taken while one was */
    uint32_t twint_fixes;   /* TWINT writes simavr left reading set (twcr_hook) */
    /* real bus timing (bus_real_timing) */
    uint8_t real_timing;
    uint64_t step_cycle;    /* the AVR cycle at which the firmware started the TWI step in flight (TWINT written) */
    uint64_t stop_cycle;    /* the cycle of the last STOP; the next START waits for the bus to be free */
    uint32_t timed;         /* TWI steps given real timing */
    uint32_t byte_steps;    /* of them, address or data bytes, and their total time, start to TWINT, AVR cycles */
    uint64_t byte_cycles;
    uint8_t *uart;
    uint32_t uart_len;
    /* a temperature ramp per chip (bus_ramp): the field served is base x (1 + alpha (T - t_ref)) at T(now) */
    struct ramp {
        uint8_t on;
        double base[3];
        double t_start_c, rate_c_per_s, alpha_per_c, t_ref_c;
        uint64_t t0_us;
    } ramp[MAX_CHIPS];
} bus_t;

/* The chip's field and temperature now, on its ramp (the model reads them when the firmware reads the chip). */
static void ramp_to_now(bus_t *b, sim_mlx_t *chip)
{
    struct ramp *r = &b->ramp[chip - b->chips];
    double t, g;
    if (!r->on) {
        return;
    }
    t = r->t_start_c + r->rate_c_per_s * (double)(b->now_us - r->t0_us) * 1e-6;
    g = 1.0 + r->alpha_per_c * (t - r->t_ref_c);
    sim_set_field(chip, r->base[0] * g, r->base[1] * g, r->base[2] * g, t);
}

static void sync_time(bus_t *b)
{
    b->now_us = b->avr->cycle * 1000000ull / b->avr->frequency;
}

static void flush_write(bus_t *b)
{
    if (b->selected && !(b->selected & 1)) {
        sync_time(b);
        sim_i2c_write(b->on, (uint8_t)(b->selected >> 1), b->wbuf, b->wlen);
    }
    b->wlen = 0;
}

static void ack(bus_t *b)
{
    avr_raise_irq(b->twi_in, avr_twi_irq_msg(TWI_COND_ACK, b->selected, 1));
}

/* The master sent an address byte (after a START or a repeated START). */
static void address_phase(bus_t *b, uint8_t addr)
{
    uint8_t k;
    flush_write(b);
    b->selected = 0;
    b->sla_w_pending = !(addr & 1);
    ++b->phases;
    if (b->reset_in && --b->reset_in == 0) {
        sync_time(b);
        sim_fault(&b->chips[b->reset_chip], SIM_FAULT_RESET, 1);
    }
    for (k = 0; k < b->n_chips && b->chips[k].addr != (addr >> 1); ++k) {
    }
    if (k == b->n_chips || b->absent[k]) {
        return;
    }
    if (b->nack_addr[k]) {
        --b->nack_addr[k];
        return;
    }
    b->on = &b->chips[k];
    b->selected = addr;
    ack(b);
    if (addr & 1) { /* the reply is fixed at SLA+R: the model answers the command written before it */
        memset(b->rbuf, 0xFF, sizeof b->rbuf);
        b->ridx = 0;
        sync_time(b);
        ramp_to_now(b, b->on);
        if (b->ff_reads) {
            --b->ff_reads;
        } else {
            sim_i2c_read(b->on, (uint8_t)(addr >> 1), b->rbuf, 9);
        }
    }
}

static void twi_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    bus_t *b = (bus_t *)param;
    avr_twi_msg_irq_t v;
    (void)irq;
    v.u.v = value;
    if (v.u.twi.msg & TWI_COND_STOP) {
        flush_write(b);
        b->selected = 0;
    }
    if (v.u.twi.msg & TWI_COND_START) {
        address_phase(b, v.u.twi.addr);
        return;
    }
    if (!b->selected) {
        return;
    }
    if (v.u.twi.msg & TWI_COND_WRITE) {
        if (b->nack_data) {
            --b->nack_data;
            return;
        }
        if (b->wlen < sizeof b->wbuf) {
            b->wbuf[b->wlen++] = v.u.twi.data;
        }
        ack(b);
    } else if (v.u.twi.msg & TWI_COND_READ) {
        uint8_t d = b->ridx < sizeof b->rbuf ? b->rbuf[b->ridx] : 0xFF;
        ++b->ridx;
        avr_raise_irq(b->twi_in, avr_twi_irq_msg(TWI_COND_READ, b->selected, d));
    }
}

/* A held bus: TWINT, just raised with the status, is taken back before the next instruction. */
static avr_cycle_count_t take_twint_back(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    bus_t *b = (bus_t *)param;
    (void)when;
    avr_clear_interrupt(avr, &b->twi0->twi);
    avr_regbit_clear(avr, b->twi0->twi.raised); /* simavr keeps TWINT until the program clears it */
    return 0;
}

/* A step held for real timing: TWINT back, with its interrupt, at the cycle the step ends on a real bus. */
static avr_cycle_count_t give_twint(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    bus_t *b = (bus_t *)param;
    (void)when;
    b->in_step = 0;
    avr_raise_interrupt(avr, &b->twi0->twi);
    return 0;
}

/* The firmware writes TWCR: a step starts when it writes TWINT with TWEN (a STOP is over once it is written). Writing
 * TWINT clears the flag on the hardware; simavr 1.6 stores the 1 written when the flag was clear (a START after a
 * STOP), so the flag reads set, with the old status, until the START's own event: it is cleared here (counted). */
static void twcr_hook(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    bus_t *b = (bus_t *)param;
    (void)addr;
    if ((v & 0x84) == 0x84 && b->twi0 && avr_regbit_get(avr, b->twi0->twi.raised)) {
        avr_regbit_clear(avr, b->twi0->twi.raised);
        ++b->twint_fixes;
    }
    if ((v & 0x84) == 0x84) {
        b->step_cycle = avr->cycle;
        b->in_step = !(v & 0x10);
    }
    if ((v & 0x94) == 0x94) {
        b->stop_cycle = avr->cycle;
    }
}

/* SCL periods, in AVR cycles, at the clock the image set: F_CPU / (16 + 2 TWBR 4^TWPS). */
static uint64_t scl_cycles(bus_t *b)
{
    uint32_t twps = b->avr->data[TWSR_ADDR] & 0x03;
    return 16u + 2u * (uint64_t)b->avr->data[TWBR_ADDR] * (1u << (2 * twps));
}

/* Holds TWINT (just raised with status value) until the step's real end; the step's time is counted. */
static void real_time_step(bus_t *b, uint32_t value)
{
    uint64_t scl = scl_cycles(b), start = b->step_cycle, due;
    if (value == 0x08) {
        uint64_t free_at = b->stop_cycle + 2 * scl; /* the STOP (one SCL period) and t_BUF after it */
        due = (start > free_at ? start : free_at) + scl;
    } else if (value == 0x10) {
        due = start + 2 * scl;
    } else {
        due = start + 9 * scl;
        ++b->byte_steps;
        b->byte_cycles += due - start;
    }
    ++b->timed;
    if (b->avr->cycle < due) {
        b->in_step = 2; /* held: give_twint ends it */
        avr_cycle_timer_register(b->avr, 0, take_twint_back, b);
        avr_cycle_timer_register(b->avr, due - b->avr->cycle, give_twint, b);
    }
}

static void twi_status_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    bus_t *b = (bus_t *)param;
    (void)irq;
    sync_time(b);
    if (value != TW_NO_INFO && b->in_step == 1) {
        b->in_step = 0;
    }
    if (value != TW_NO_INFO && b->real_timing && b->twi0 && !b->hang_for_us && b->now_us >= b->hang_until_us) {
        real_time_step(b, value);
    }
    if (value != TW_NO_INFO && b->hang_for_us) {
        b->hang_until_us = b->now_us + b->hang_for_us;
        b->hang_for_us = 0;
    }
    if (value != TW_NO_INFO && b->now_us < b->hang_until_us && b->twi0) {
        ++b->held;
        avr_cycle_timer_register(b->avr, 0, take_twint_back, b);
    }
    if (!b->sla_w_pending || value == 0x08 || value == 0x10) {
        return; /* START / repeated START come before the address */
    }
    b->sla_w_pending = 0;
    if (value == 0x28 || value == 0x30) {
        b->avr->data[TWSR_ADDR] = (uint8_t)((b->avr->data[TWSR_ADDR] & 0x07) | (value - 0x10));
        ++b->status_fixes;
    }
}

static void uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    bus_t *b = (bus_t *)param;
    (void)irq;
    if (b->uart_len < UART_CAP) {
        b->uart[b->uart_len++] = (uint8_t)value;
    }
}

/* (UBRR + 1) x (U2X ? 8 : 16) cycles per bit; start + data + parity (UPM) + stop bits per byte. */
static void uart_baud_hook(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    static const uint32_t databits[4] = {5, 6, 7, 8};
    bus_t *b = (bus_t *)param;
    uint8_t a = avr->data[UCSR0A_ADDR], c = avr->data[UCSR0C_ADDR];
    uint32_t ubrr = avr->data[UBRR0L_ADDR] | ((uint32_t)(avr->data[UBRR0H_ADDR] & 0x0F) << 8);
    uint32_t bit = (ubrr + 1) * ((a & 0x02) ? 8u : 16u);
    uint32_t word = 1u + databits[(c >> 1) & 3] + (((c >> 4) & 3) ? 1u : 0u) + ((c & 0x08) ? 2u : 1u);
    (void)addr;
    (void)v;
    if (b->uart0) {
        b->uart0->cycles_per_byte = bit * word;
    }
}

static avr_io_t *find_io(avr_t *avr, const char *kind)
{
    avr_io_t *io;
    for (io = avr->io_port; io; io = io->next) {
        if (io->kind && !strcmp(io->kind, kind)) {
            return io;
        }
    }
    return NULL;
}

static void hook_up(bus_t *b)
{
    uint32_t flags = 0;
    b->twi_in = avr_io_getirq(b->avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(b->avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), twi_out_hook, b);
    avr_irq_register_notify(avr_io_getirq(b->avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_STATUS), twi_status_hook, b);
    b->twi0 = (avr_twi_t *)find_io(b->avr, "twi");
    b->uart0 = (avr_uart_t *)find_io(b->avr, "uart"); /* the first UART on the list is USART0 */
    avr_register_io_write(b->avr, TWCR_ADDR, twcr_hook, b);
    avr_register_io_write(b->avr, UCSR0A_ADDR, uart_baud_hook, b);
    avr_register_io_write(b->avr, UCSR0C_ADDR, uart_baud_hook, b);
    avr_register_io_write(b->avr, UBRR0L_ADDR, uart_baud_hook, b);
    avr_ioctl(b->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags); /* no stdio echo */
    b->uart_in = avr_io_getirq(b->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(b->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out_hook, b);
}

/* ---- the API Python calls ---- */

bus_t *bus_open(const char *hex_path, uint8_t addr7, uint32_t f_cpu_hz)
{
    ihex_chunk_p chunk = NULL;
    int n = read_ihex_chunks(hex_path, &chunk);
    bus_t *b;
    int k;
    if (n <= 0) {
        return NULL;
    }
    b = (bus_t *)calloc(1, sizeof *b);
    b->uart = (uint8_t *)malloc(UART_CAP);
    b->avr = avr_make_mcu_by_name("atmega328p");
    if (!b->avr || !b->uart) {
        free(b->uart);
        free(b);
        free_ihex_chunks(chunk);
        return NULL;
    }
    avr_init(b->avr);
    b->avr->frequency = f_cpu_hz;
    b->avr->log = 0;
    for (k = 0; k < n; ++k) {
        if (chunk[k].baseaddr < 0x10000) { /* flash; EEPROM chunks sit at 0x810000 */
            avr_loadcode(b->avr, chunk[k].data, chunk[k].size, chunk[k].baseaddr);
        }
    }
    free_ihex_chunks(chunk);
    sim_init(&b->chips[0], addr7, &b->now_us);
    b->n_chips = 1;
    b->on = &b->chips[0];
    hook_up(b);
    return b;
}

/* The EEPROM's bytes from offset on (what a .eep holds; avrdude would write it): straight into simavr's EEPROM
 * module (its ioctl is answered by another module first in Debian's 1.6). 0 when done. */
int bus_eeprom_set(bus_t *b, uint16_t offset, const uint8_t *data, uint32_t len)
{
    avr_eeprom_t *ee = (avr_eeprom_t *)find_io(b->avr, "eeprom");
    if (!ee || (uint32_t)offset + len > ee->size) {
        return -1;
    }
    memcpy(ee->eeprom + offset, data, len);
    return 0;
}

/* len bytes of the EEPROM from offset into out. 0 when done. */
int bus_eeprom_get(bus_t *b, uint16_t offset, uint8_t *out, uint32_t len)
{
    avr_eeprom_t *ee = (avr_eeprom_t *)find_io(b->avr, "eeprom");
    if (!ee || (uint32_t)offset + len > ee->size) {
        return -1;
    }
    memcpy(out, ee->eeprom + offset, len);
    return 0;
}

/* Run until simulated time t_us; returns the core's state (sim_avr.h: cpu_Done 5, cpu_Crashed 6). */
int bus_run_until(bus_t *b, uint64_t t_us)
{
    uint64_t end = t_us * b->avr->frequency / 1000000u;
    int state = b->avr->state;
    while (b->avr->cycle < end && state != cpu_Done && state != cpu_Crashed) {
        state = avr_run(b->avr);
    }
    return state;
}

uint64_t bus_time_us(bus_t *b)
{
    sync_time(b);
    return b->now_us;
}

uint32_t bus_take_uart(bus_t *b, uint8_t *out, uint32_t cap)
{
    uint32_t n = b->uart_len < cap ? b->uart_len : cap;
    memcpy(out, b->uart, n);
    memmove(b->uart, b->uart + n, b->uart_len - n);
    b->uart_len -= n;
    return n;
}

/* Another chip model on the bus at addr7 (same power-on state as the first); its index, -1 when full. */
int bus_add_chip(bus_t *b, uint8_t addr7)
{
    if (b->n_chips == MAX_CHIPS) {
        return -1;
    }
    sim_init(&b->chips[b->n_chips], addr7, &b->now_us);
    return b->n_chips++;
}

/* The chip the per-chip calls below act on. */
void bus_target(bus_t *b, uint8_t k) { b->target = k < b->n_chips ? k : 0; }
#define CHIP (&b->chips[b->target])
void bus_send_uart(bus_t *b, uint8_t c) { avr_raise_irq(b->uart_in, c); }
void bus_set_field(bus_t *b, double bx, double by, double bz, double t_c)
{
    b->ramp[b->target].on = 0;
    sim_set_field(CHIP, bx, by, bz, t_c);
}
/* From now on the target's temperature runs t_start_c + rate x elapsed and its field (bx, by, bz) x (1 + alpha
 * (T - t_ref_c)): the magnet's remanence (and the chip's gain) drifting with it. bus_set_field ends it. */
void bus_ramp(bus_t *b, double bx, double by, double bz, double t_start_c, double rate_c_per_s, double alpha_per_c,
              double t_ref_c)
{
    struct ramp *r = &b->ramp[b->target];
    sync_time(b);
    r->base[0] = bx;
    r->base[1] = by;
    r->base[2] = bz;
    r->t_start_c = t_start_c;
    r->rate_c_per_s = rate_c_per_s;
    r->alpha_per_c = alpha_per_c;
    r->t_ref_c = t_ref_c;
    r->t0_us = b->now_us;
    r->on = 1;
    ramp_to_now(b, CHIP);
}
void bus_chip_fault(bus_t *b, int fault, uint16_t count) { sync_time(b); sim_fault(CHIP, (enum sim_fault)fault, count); }
void bus_nack(bus_t *b, uint32_t addr_phases, uint32_t data_bytes) { b->nack_addr[b->target] = addr_phases; b->nack_data = data_bytes; }
void bus_ff_reads(bus_t *b, uint32_t n) { b->ff_reads = n; }
void bus_reset_in(bus_t *b, uint32_t n) { b->reset_in = n; b->reset_chip = b->target; }
void bus_hang_us(bus_t *b, uint64_t us) { b->hang_for_us = us; }
void bus_absent(bus_t *b, int absent) { b->absent[b->target] = (uint8_t)absent; }
/* The chip's oscillator: its conversions take this many times the table's time from now on. */
void bus_clock_scale(bus_t *b, double scale) { CHIP->clock_scale = scale; }
uint32_t bus_status_fixes(bus_t *b) { return b->status_fixes; }
uint32_t bus_phases(bus_t *b) { return b->phases; }
uint32_t bus_held(bus_t *b) { return b->held; }
/* The profiler: every pc_period cycles, a sample of where the CPU is, its program counter (a histogram by word
 * address, which Python maps to the ELF's functions), and apart whether a TWI step is in flight then (the bus's busy
 * time, which the CPU spends waiting on it or, when the transfer runs from its interrupt, on other work). */
static avr_cycle_count_t pc_sample(struct avr_t *avr, avr_cycle_count_t when, void *param)
{
    bus_t *b = (bus_t *)param;
    if (b->in_step) {
        ++b->bus_samples;
    }
    if (b->pc_hist && avr->pc / 2 < PROFILE_WORDS) {
        ++b->pc_hist[avr->pc / 2];
    }
    return when + b->pc_period;
}
uint32_t bus_profile_bus_samples(bus_t *b) { return b->bus_samples; }
/* Start the profiler: hist (PROFILE_WORDS counters, one per flash word) from now on, a sample every period cycles. */
void bus_profile(bus_t *b, uint32_t *hist, uint32_t period)
{
    b->bus_samples = 0;
    b->pc_hist = hist;
    b->pc_period = period;
    avr_cycle_timer_register(b->avr, period, pc_sample, b);
}
/* Real I2C timing from now on (on != 0), or simavr's own. */
void bus_real_timing(bus_t *b, int on) { b->real_timing = (uint8_t)(on != 0); }
/* Steps given real timing, and the bytes' mean time from start to TWINT, us. */
uint32_t bus_timed_steps(bus_t *b) { return b->timed; }
double bus_byte_us(bus_t *b) { return b->byte_steps ? (double)b->byte_cycles * 1e6 / b->avr->frequency / b->byte_steps : 0.0; }
uint32_t bus_uart_cycles_per_byte(bus_t *b) { return b->uart0 ? (uint32_t)b->uart0->cycles_per_byte : 0; }
uint16_t bus_chip_register(bus_t *b, uint8_t reg) { return CHIP->reg[reg & 31]; }
int bus_chip_mode(bus_t *b) { return CHIP->mode; }
/* One conversion of the running measurement's channels with the chip's current registers, us. */
double bus_conversion_us(bus_t *b) { return sim_conversion_us(CHIP, CHIP->zyxt) * CHIP->clock_scale; }
/* Conversions the chip has completed since its burst started. */
uint64_t bus_conversions(bus_t *b)
{
    double conv = bus_conversion_us(b);
    if (CHIP->mode != SIM_BURST || conv <= 0.0) {
        return 0;
    }
    return (uint64_t)((double)(bus_time_us(b) - CHIP->t_start) / conv);
}

void bus_close(bus_t *b)
{
    avr_terminate(b->avr);
    free(b->uart);
    free(b);
}
