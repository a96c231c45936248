/* The RP2040 boards' clocks from their 12 MHz crystals (clocks.c): 0, or -1 when a ready bit never came. */
#ifndef CLOCKS_H
#define CLOCKS_H

int clocks_init(void);

#endif
