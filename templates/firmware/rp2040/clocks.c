/* The RP2040 boards' clocks (RP2040 datasheet 2.15 clocks, 2.16 XOSC, 2.18 PLL), from their 12 MHz crystals (the
 * Pico's, the QT Py RP2040's and the XIAO RP2040's): clk_ref from the crystal, clk_sys 125 MHz from PLL_SYS
 * (12 MHz x 125 / 6 / 2), clk_usb 48 MHz from PLL_USB (12 MHz x 100 / 5 / 5) as USB needs it, clk_peri from clk_sys,
 * and the watchdog's tick at 1 us from clk_ref, which TIMER counts. At reset everything runs from the ring
 * oscillator (about 6 MHz), USB cannot run and TIMER does not count. rp2040js runs at 125 MHz whatever is set, with
 * the crystal, the locks and the clock switches ready at once: there this proves the sequence ends, not its timing.
 * Every wait is a poll of a ready bit the datasheet gives, bounded by a count (the crystal's counter does not run in
 * the emulator, so no wait counts on it). */
#include <stdint.h>

#include "clocks.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define CLR(a) (*(volatile uint32_t *)((a) + 0x3000u)) /* the atomic clear alias (2.1.2) */
#define RESETS 0x4000c000u
#define RESET_DONE (RESETS + 0x8u)
#define RESET_PLL_SYS (1u << 12)
#define RESET_PLL_USB (1u << 13)

#define XOSC 0x40024000u
#define XOSC_CTRL (XOSC + 0x00u)
#define XOSC_STATUS (XOSC + 0x04u)
#define XOSC_STARTUP (XOSC + 0x0cu)

#define PLL_SYS 0x40028000u
#define PLL_USB 0x4002c000u
#define PLL_CS 0x0u
#define PLL_PWR 0x4u
#define PLL_FBDIV 0x8u
#define PLL_PRIM 0xcu
#define PLL_PWR_PD (1u << 0)
#define PLL_PWR_POSTDIVPD (1u << 3)
#define PLL_PWR_VCOPD (1u << 5)
#define PLL_LOCK (1u << 31)

#define CLOCKS 0x40008000u
#define CLK_REF_CTRL (CLOCKS + 0x30u)
#define CLK_REF_DIV (CLOCKS + 0x34u)
#define CLK_REF_SELECTED (CLOCKS + 0x38u)
#define CLK_SYS_CTRL (CLOCKS + 0x3cu)
#define CLK_SYS_DIV (CLOCKS + 0x40u)
#define CLK_SYS_SELECTED (CLOCKS + 0x44u)
#define CLK_PERI_CTRL (CLOCKS + 0x48u)
#define CLK_USB_CTRL (CLOCKS + 0x54u)
#define CLK_USB_DIV (CLOCKS + 0x58u)
#define CLK_ENABLE (1u << 11)
#define WATCHDOG_TICK (0x40058000u + 0x2cu)

#define XTAL_HZ 12000000u
#define SPINS 1000000u /* the most polls of one ready bit */

static int wait_set(uint32_t reg, uint32_t mask, uint32_t want) {
    for (uint32_t i = 0; i < SPINS; i++) {
        if ((REG(reg) & mask) == want) return 0;
    }
    return -1;
}

static int pll_start(uint32_t pll, uint32_t reset, uint32_t fbdiv, uint32_t post1, uint32_t post2) {
    REG(RESETS + 0x2000u) = reset; /* into reset (the set alias) and out, as the datasheet's sequence begins */
    CLR(RESETS) = reset;
    if (wait_set(RESET_DONE, reset, reset)) return -1;
    REG(pll + PLL_CS) = 1u;                         /* REFDIV 1: the crystal straight to the PFD */
    REG(pll + PLL_FBDIV) = fbdiv;
    CLR(pll + PLL_PWR) = PLL_PWR_PD | PLL_PWR_VCOPD; /* power the PLL and its VCO */
    if (wait_set(pll + PLL_CS, PLL_LOCK, PLL_LOCK)) return -1;
    REG(pll + PLL_PRIM) = (post1 << 16) | (post2 << 12);
    CLR(pll + PLL_PWR) = PLL_PWR_POSTDIVPD;
    return 0;
}

int clocks_init(void) {
    REG(XOSC_CTRL) = 0xaa0u;                                 /* FREQ_RANGE 1-15 MHz */
    REG(XOSC_STARTUP) = (XTAL_HZ / 1000u + 128u) / 256u;     /* about 1 ms, in units of 256 cycles */
    REG(XOSC_CTRL) = 0xaa0u | (0xfabu << 12);                /* ENABLE */
    if (wait_set(XOSC_STATUS, 1u << 31, 1u << 31)) return -1; /* STABLE */

    CLR(CLK_SYS_CTRL) = 1u;                                  /* clk_sys on clk_ref while its PLL changes */
    if (wait_set(CLK_SYS_SELECTED, 0x3u, 0x1u)) return -1;
    REG(CLK_REF_DIV) = 1u << 8;
    REG(CLK_REF_CTRL) = 2u;                                  /* clk_ref from the crystal */
    if (wait_set(CLK_REF_SELECTED, 0x7u, 1u << 2)) return -1;

    if (pll_start(PLL_SYS, RESET_PLL_SYS, 125u, 6u, 2u)) return -1; /* VCO 1500 MHz, 125 MHz out */
    if (pll_start(PLL_USB, RESET_PLL_USB, 100u, 5u, 5u)) return -1; /* VCO 1200 MHz, 48 MHz out */

    REG(CLK_SYS_DIV) = 1u << 8;
    REG(CLK_SYS_CTRL) = 0u << 5;                             /* AUXSRC pll_sys; the glitchless mux holds clk_ref */
    REG(CLK_SYS_CTRL) = (0u << 5) | 1u;                      /* SRC aux */
    if (wait_set(CLK_SYS_SELECTED, 0x3u, 0x2u)) return -1;
    REG(CLK_USB_DIV) = 1u << 8;
    REG(CLK_USB_CTRL) = CLK_ENABLE | (0u << 5);              /* clk_usb from pll_usb */
    REG(CLK_PERI_CTRL) = CLK_ENABLE | (0u << 5);             /* clk_peri from clk_sys */
    REG(WATCHDOG_TICK) = (1u << 9) | (XTAL_HZ / 1000000u);   /* ENABLE, 12 cycles of clk_ref: 1 us */
    return 0;
}
