/* The RP2040 harness's USB smoke image (tests/export/test_rp2040_harness.py): the CDC-ACM device (usb_cdc.c)
 * enumerates on rp2040js's host, announces itself, and echoes each line it receives in capitals. */
#include <stdint.h>

#include "clocks.h"
#include "usb_cdc.h"

int main(void) {
    if (clocks_init() != 0) return 1;
    cdc_init();
    int announced = 0;
    for (;;) {
        cdc_poll();
        if (cdc_configured() && !announced) {
            static const uint8_t hello[] = "magfab rp2040 usb\n";
            announced = cdc_write(hello, sizeof hello - 1u) == sizeof hello - 1u;
        }
        int c = cdc_read();
        if (c >= 0) {
            uint8_t u = (uint8_t)(c >= 'a' && c <= 'z' ? c - 32 : c);
            while (cdc_write(&u, 1u) == 0u) cdc_poll();
        }
    }
}
