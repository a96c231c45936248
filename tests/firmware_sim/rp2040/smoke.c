/* The RP2040 harness's smoke image (tests/export/test_rp2040_harness.py): the toolchain, the UF2 file and the
 * emulator proven end to end before any readout firmware runs on them. After boot2 the core starts at the vector
 * table (0x10000100) and start.c runs main, which takes UART0 out of reset (RP2040 datasheet 2.14, RESETS; the
 * atomic clear alias at +0x3000, 2.1.2), sets it to 115200 baud 8N1 (4.2, the PL011's IBRD/FBRD at 125 MHz, LCR_H,
 * CR) and sends one line. */
#include <stdint.h>

#define REG(a) (*(volatile uint32_t *)(a))
#define RESETS 0x4000c000u
#define RESETS_CLR (RESETS + 0x3000u)
#define RESET_DONE (RESETS + 0x8u)
#define UART0 0x40034000u
#define UART0_RESET (1u << 22)

static void put(char c) {
    while (REG(UART0 + 0x18u) & (1u << 5)) { /* TXFF: the FIFO is full */
    }
    REG(UART0) = (uint8_t)c;
}

int main(void) {
    REG(RESETS_CLR) = UART0_RESET;
    while (!(REG(RESET_DONE) & UART0_RESET)) {
    }
    REG(UART0 + 0x24u) = 67u;                          /* IBRD: 125e6 / (16 x 115200) = 67.8 */
    REG(UART0 + 0x28u) = 52u;                          /* FBRD: 0.817 x 64 */
    REG(UART0 + 0x2cu) = (3u << 5) | (1u << 4);        /* LCR_H: 8 bits, FIFOs on */
    REG(UART0 + 0x30u) = (1u << 0) | (1u << 8) | (1u << 9); /* CR: UARTEN, TXE, RXE */
    for (const char *s = "magfab rp2040 smoke\n"; *s; s++) put(*s);
    for (;;) {
        __asm__ volatile("wfi");
    }
}
