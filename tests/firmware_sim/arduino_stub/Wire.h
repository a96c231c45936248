/* A minimal stand-in for the Arduino Wire library (the AVR core's API, with the timeout extension). */
#ifndef WIRE_STUB_H
#define WIRE_STUB_H

#include "Arduino.h"

#define WIRE_HAS_TIMEOUT 1

class TwoWire {
public:
    void begin(void);
    void setClock(uint32_t hz);
    void setWireTimeout(uint32_t timeout_us, bool reset_with_timeout);
    bool getWireTimeoutFlag(void);
    void clearWireTimeoutFlag(void);
    void beginTransmission(uint8_t address);
    size_t write(const uint8_t *data, size_t len);
    uint8_t endTransmission(bool send_stop);
    uint8_t requestFrom(uint8_t address, uint8_t quantity);
    int available(void);
    int read(void);
};
extern TwoWire Wire;

#endif
