/* Constant tables in flash on AVR (where a plain const array would be copied into the 2 KB of RAM),
 * ordinary constants everywhere else. */
#ifndef MF_ROM_H
#define MF_ROM_H

#if defined(__AVR__)
#include <avr/pgmspace.h>
#define MF_ROM PROGMEM
#define mf_rom_float(p) pgm_read_float(p)
#define mf_rom_byte(p) pgm_read_byte(p)
#else
#define MF_ROM
#define mf_rom_float(p) (*(p))
#define mf_rom_byte(p) (*(p))
#endif

#endif
