/* A USB CDC-ACM serial device for the RP2040, written from the datasheet's USB chapter (4.1) and the USB CDC 1.2 /
 * PSTN 1.2 class specifications (usb_cdc.h): polled, no interrupts, full speed, one buffer per endpoint. It is the
 * readout firmware's serial link on the RP2040 boards (their USB is the RP2040's own); the harness's images
 * (tests/firmware_sim/rp2040) prove it on rp2040js's CDC host.
 *
 * DPRAM (4.1.2.5, DPSRAM): the setup packet at 0x000; each endpoint's control register (EP1 IN at 0x008, EPn IN at
 * 0x008 + 8(n-1), OUT 4 bytes on); each endpoint's buffer control (EPn IN at 0x080 + 8n, OUT 4 bytes on); EP0's buffer
 * at 0x100; the others' 64-byte buffers from 0x180. */
#include "usb_cdc.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define RESETS_CLR (0x4000c000u + 0x3000u)
#define RESET_DONE (0x4000c000u + 0x8u)
#define RESET_USBCTRL (1u << 24)

#define DPRAM 0x50100000u
#define USB 0x50110000u
#define ADDR_ENDP (USB + 0x00u)
#define MAIN_CTRL (USB + 0x40u)
#define SIE_CTRL (USB + 0x4cu)
#define SIE_STATUS (USB + 0x50u)
#define BUFF_STATUS (USB + 0x58u)
#define USB_MUXING (USB + 0x74u)
#define USB_PWR (USB + 0x78u)

#define SIE_SETUP_REC (1u << 17)
#define SIE_BUS_RESET (1u << 19)
#define EP_ENABLE (1u << 31)
#define EP_INT_PER_BUFFER (1u << 29)
#define EP_BULK (2u << 26)
#define EP_INTERRUPT (3u << 26)
#define BUF_FULL (1u << 15)
#define BUF_LAST (1u << 14)
#define BUF_DATA1 (1u << 13)
#define BUF_AVAILABLE (1u << 10)

#define EP_CTRL_IN(n) (DPRAM + 0x008u + 8u * ((n) - 1u))
#define EP_CTRL_OUT(n) (DPRAM + 0x00cu + 8u * ((n) - 1u))
#define BUF_CTRL_IN(n) (DPRAM + 0x080u + 8u * (n))
#define BUF_CTRL_OUT(n) (DPRAM + 0x084u + 8u * (n))
#define EP0_BUF (DPRAM + 0x100u)
#define EP1_BUF 0x180u /* bulk IN: data to the host */
#define EP2_BUF 0x1c0u /* bulk OUT: data from the host */
#define EP3_BUF 0x200u /* interrupt IN: CDC notifications (none sent) */

static const uint8_t device_descriptor[18] = {
    18, 1, 0x00, 0x02, 0x02, 0x00, 0x00, 64, /* USB 2.0, class CDC, EP0 64 bytes */
    0x8a, 0x2e, 0x0a, 0x00, 0x00, 0x01,      /* the Pico SDK's CDC ID (0x2E8A:0x000A), device 1.00 */
    1, 2, 3, 1};                             /* manufacturer, product, serial strings; one configuration */

static const uint8_t config_descriptor[67] = {
    9, 2, 67, 0, 2, 1, 0, 0x80, 50,                   /* 2 interfaces, bus powered, 100 mA */
    9, 4, 0, 0, 1, 0x02, 0x02, 0x00, 0,               /* interface 0: communications, ACM */
    5, 0x24, 0x00, 0x10, 0x01,                        /* header: CDC 1.10 */
    5, 0x24, 0x01, 0x00, 1,                           /* call management: data on interface 1 */
    4, 0x24, 0x02, 0x02,                              /* ACM: line coding and control line state */
    5, 0x24, 0x06, 0, 1,                              /* union: 0 controls 1 */
    7, 5, 0x83, 0x03, 8, 0, 16,                       /* EP3 IN interrupt, 8 bytes */
    9, 4, 1, 0, 2, 0x0a, 0x00, 0x00, 0,               /* interface 1: CDC data */
    7, 5, 0x02, 0x02, 64, 0, 0,                       /* EP2 OUT bulk */
    7, 5, 0x81, 0x02, 64, 0, 0};                      /* EP1 IN bulk */

static char serial[17] = "0";
static const char *const strings[] = {"", "magfab", "magfab RP2040 readout", serial};

void cdc_serial(const uint8_t id[8]) {
    static const char hex[] = "0123456789ABCDEF";
    for (uint32_t k = 0; k < 8u; k++) serial[2u * k] = hex[id[k] >> 4], serial[2u * k + 1u] = hex[id[k] & 15u];
    serial[16] = 0;
}

static uint8_t string_buf[64];
static const uint8_t *ep0_data;
static uint32_t ep0_left;
static uint32_t ep0_pid, ep1_pid;
static uint32_t pending_address;
static int configured, ep1_busy, ep2_armed;
static uint32_t ep2_pid;
#define RING 256u /* power of two */
static uint8_t tx_ring[RING], rx_ring[RING];
static uint32_t tx_head, tx_tail, rx_head, rx_tail;
static const uint8_t line_coding[7] = {0x00, 0xc2, 0x01, 0x00, 0, 0, 8}; /* 115200 8N1 */

static void arm(uint32_t ctrl_reg, uint32_t ctrl) {
    REG(ctrl_reg) = ctrl;
    for (volatile int i = 0; i < 4; i++) { /* the datasheet's gap before AVAILABLE when clk_sys outruns clk_usb */
    }
    REG(ctrl_reg) = ctrl | BUF_AVAILABLE;
}

static void ep0_next(void) {
    uint32_t n = ep0_left < 64u ? ep0_left : 64u;
    for (uint32_t i = 0; i < n; i++) ((volatile uint8_t *)EP0_BUF)[i] = ep0_data[i];
    ep0_data += n;
    ep0_left -= n;
    arm(BUF_CTRL_IN(0), n | BUF_FULL | (ep0_pid ? BUF_DATA1 : 0u));
    ep0_pid ^= 1u;
}

static void ep0_send(const uint8_t *p, uint32_t n, uint32_t asked) {
    ep0_data = p;
    ep0_left = n < asked ? n : asked;
    ep0_pid = 1u; /* the first packet after SETUP is DATA1 */
    if (ep0_left) arm(BUF_CTRL_OUT(0), BUF_DATA1); /* a data stage IN: the host's zero-length status OUT taken */
    ep0_next();
}

static uint32_t string_descriptor(uint32_t index) {
    if (index == 0) {
        string_buf[0] = 4, string_buf[1] = 3, string_buf[2] = 0x09, string_buf[3] = 0x04; /* English (US) */
        return 4;
    }
    const char *s = index < sizeof strings / sizeof strings[0] ? strings[index] : "";
    uint32_t n = 2;
    for (; *s && n + 2 <= sizeof string_buf; s++, n += 2) string_buf[n] = (uint8_t)*s, string_buf[n + 1] = 0;
    string_buf[0] = (uint8_t)n, string_buf[1] = 3;
    return n;
}

static void setup(void) {
    volatile uint8_t *p = (volatile uint8_t *)DPRAM;
    uint32_t type = p[0], request = p[1], value = p[2] | (p[3] << 8), length = p[6] | (p[7] << 8);
    if ((type & 0x60u) == 0x00u && request == 0x05u) { /* SET_ADDRESS: after its status stage */
        pending_address = value & 0x7fu;
        ep0_send(0, 0, 0);
    } else if ((type & 0x60u) == 0x00u && request == 0x06u) { /* GET_DESCRIPTOR */
        uint32_t kind = value >> 8;
        if (kind == 1u) {
            ep0_send(device_descriptor, sizeof device_descriptor, length);
        } else if (kind == 2u) {
            ep0_send(config_descriptor, sizeof config_descriptor, length);
        } else if (kind == 3u) {
            ep0_send(string_buf, string_descriptor(value & 0xffu), length);
        } else {
            ep0_send(0, 0, 0);
        }
    } else if ((type & 0x60u) == 0x00u && request == 0x09u) { /* SET_CONFIGURATION */
        configured = 1;
        ep1_pid = 0u, ep2_pid = 0u, ep1_busy = 0, ep2_armed = 0;
        ep0_send(0, 0, 0);
    } else if ((type & 0x60u) == 0x20u && request == 0x21u) { /* GET_LINE_CODING */
        ep0_send(line_coding, sizeof line_coding, length);
    } else { /* SET_LINE_CODING's data is taken and ignored; SET_CONTROL_LINE_STATE and the rest: a ZLP */
        if (length) arm(BUF_CTRL_OUT(0), (length < 64u ? length : 64u) | BUF_DATA1);
        ep0_send(0, 0, 0);
    }
}

void cdc_init(void) {
    REG(RESETS_CLR) = RESET_USBCTRL;
    while (!(REG(RESET_DONE) & RESET_USBCTRL)) {
    }
    for (uint32_t a = 0; a < 4096u; a += 4u) REG(DPRAM + a) = 0u;
    REG(USB_MUXING) = (1u << 0) | (1u << 3);              /* TO_PHY, SOFTCON */
    REG(USB_PWR) = (1u << 2) | (1u << 3);                 /* VBUS detected, by override */
    REG(EP_CTRL_IN(1)) = EP_ENABLE | EP_INT_PER_BUFFER | EP_BULK | EP1_BUF;
    REG(EP_CTRL_OUT(2)) = EP_ENABLE | EP_INT_PER_BUFFER | EP_BULK | EP2_BUF;
    REG(EP_CTRL_IN(3)) = EP_ENABLE | EP_INT_PER_BUFFER | EP_INTERRUPT | EP3_BUF;
    REG(MAIN_CTRL) = 1u;                                  /* CONTROLLER_EN, device */
    REG(SIE_CTRL) = (1u << 29) | (1u << 16);              /* EP0_INT_1BUF, PULLUP_EN */
}

void cdc_poll(void) {
    uint32_t status = REG(SIE_STATUS);
    if (status & SIE_BUS_RESET) {
        REG(SIE_STATUS) = SIE_BUS_RESET;
        REG(ADDR_ENDP) = 0u;
        pending_address = 0u, configured = 0, ep1_busy = 0, ep2_armed = 0;
    }
    if (status & SIE_SETUP_REC) {
        REG(SIE_STATUS) = SIE_SETUP_REC;
        setup();
    }
    uint32_t done = REG(BUFF_STATUS);
    if (done) REG(BUFF_STATUS) = done;
    if (done & (1u << 0)) { /* EP0 IN */
        if (pending_address) REG(ADDR_ENDP) = pending_address, pending_address = 0u;
        if (ep0_left) ep0_next();
    }
    if (done & (1u << 2)) ep1_busy = 0; /* EP1 IN: the packet went */
    if (done & (1u << 5)) {             /* EP2 OUT: the host's bytes, into the receive ring (armed only with room) */
        uint32_t n = REG(BUF_CTRL_OUT(2)) & 0x3ffu;
        volatile uint8_t *buf = (volatile uint8_t *)(DPRAM + EP2_BUF);
        for (uint32_t i = 0; i < n; i++) rx_ring[rx_head++ & (RING - 1u)] = buf[i];
        ep2_armed = 0;
    }
    if (!configured) return;
    if (!ep2_armed && RING - (rx_head - rx_tail) >= 64u) {
        ep2_armed = 1;
        arm(BUF_CTRL_OUT(2), 64u | (ep2_pid ? BUF_DATA1 : 0u));
        ep2_pid ^= 1u;
    }
    if (!ep1_busy && tx_head != tx_tail) { /* the next packet: up to 64 queued bytes */
        uint32_t n = 0;
        volatile uint8_t *buf = (volatile uint8_t *)(DPRAM + EP1_BUF);
        for (; n < 64u && tx_tail != tx_head; n++) buf[n] = tx_ring[tx_tail++ & (RING - 1u)];
        ep1_busy = 1;
        arm(BUF_CTRL_IN(1), n | BUF_FULL | (ep1_pid ? BUF_DATA1 : 0u));
        ep1_pid ^= 1u;
    }
}

int cdc_configured(void) { return configured; }

int cdc_read(void) { return rx_tail == rx_head ? -1 : rx_ring[rx_tail++ & (RING - 1u)]; }

uint32_t cdc_write(const uint8_t *data, uint32_t len) {
    uint32_t n = 0;
    for (; n < len && tx_head - tx_tail < RING; n++) tx_ring[tx_head++ & (RING - 1u)] = data[n];
    return n;
}

