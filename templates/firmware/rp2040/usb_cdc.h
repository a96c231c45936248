/* The RP2040's USB as a CDC-ACM serial port (usb_cdc.c): call cdc_poll() often; bytes queue both ways in 256-byte
 * rings, sent in packets of up to 64 and received while the ring has room for a whole packet. */
#ifndef USB_CDC_H
#define USB_CDC_H

#include <stdint.h>

void cdc_init(void);
void cdc_serial(const uint8_t id[8]); /* the serial number string: these 8 bytes in upper-case hex (before cdc_init) */
void cdc_poll(void);
int cdc_configured(void);                            /* the host has set the configuration */
int cdc_read(void);                                  /* the next byte from the host, or -1 */
uint32_t cdc_write(const uint8_t *data, uint32_t len); /* queues what fits; returns how many */

#endif
