/* A minimal stand-in for the Arduino core's Arduino.h: just what the magfab sketch uses, so the test suite
 * can compile the sketch on the host (g++ -fsyntax-only) without an Arduino installation. */
#ifndef ARDUINO_STUB_H
#define ARDUINO_STUB_H

#include <stddef.h>
#include <stdint.h>

#define LOW 0
#define HIGH 1
static const uint8_t SDA = 18;
static const uint8_t SCL = 19;

unsigned long micros(void);
void digitalWrite(uint8_t pin, uint8_t value);

class HardwareSerial {
public:
    void begin(unsigned long baud);
    int available(void);
    int read(void);
    size_t write(const uint8_t *data, size_t len);
};
extern HardwareSerial Serial;

#endif
