/* The RP2040 images' start (rp2040.ld): after boot2 the core loads the stack pointer and the reset handler from the
 * vector table at 0x10000100; the handler copies the initialised data to SRAM, zeroes the rest, and runs main(). */
#include <stdint.h>

extern uint32_t __stack_top, __data_start, __data_end, __data_load, __bss_start, __bss_end;
int main(void);
void reset_handler(void);

__attribute__((section(".vectors"), used)) const void *const vectors[16] = {&__stack_top, (void *)reset_handler};

void reset_handler(void) {
    for (uint32_t *d = &__data_start, *s = &__data_load; d < &__data_end;) *d++ = *s++;
    for (uint32_t *b = &__bss_start; b < &__bss_end;) *b++ = 0u;
    (void)main();
    for (;;) {
    }
}
