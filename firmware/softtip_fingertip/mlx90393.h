// Command-level I2C driver for the Melexis MLX90393, written from the datasheet
// (rev. 006): every command is one write of the command bytes followed, after a
// repeated start, by a read of the status byte and any data words (MSB first).
#ifndef SOFTTIP_MLX90393_H
#define SOFTTIP_MLX90393_H

#include <Arduino.h>
#include <Wire.h>

#include "protocol.h"

namespace softtip {

// Status byte bits (datasheet, "Status byte"); bits 7:5 report the mode
// (burst, wake-up on change, single measurement) and are not checked.
const uint8_t MLX_STATUS_ERROR = 0x10;
const uint8_t MLX_STATUS_SED = 0x08;
const uint8_t MLX_STATUS_RS = 0x04;
const uint8_t MLX_STATUS_D = 0x03;  // RR / RM: the response holds 2 * D + 2 data bytes

// Commands; SM and RM take the zyxt axis mask in their low nibble.
const uint8_t MLX_CMD_SM = 0x30;
const uint8_t MLX_CMD_RM = 0x40;
const uint8_t MLX_CMD_RR = 0x50;
const uint8_t MLX_CMD_WR = 0x60;
const uint8_t MLX_CMD_EX = 0x80;
const uint8_t MLX_CMD_RT = 0xF0;
const uint8_t MLX_AXIS_T = 0x01;
const uint8_t MLX_AXES_XYZ = 0x0E;

class Mlx90393 {
  public:
    explicit Mlx90393(uint8_t address = 0x0C) : address_(address) {}
    uint8_t address() const { return address_; }

    // Each returns ChipStatus flags (0 on success) for the transfer and status byte.
    uint8_t exit_mode();
    uint8_t reset();
    uint8_t read_register(uint8_t reg, uint16_t *value);
    uint8_t write_register(uint8_t reg, uint16_t value);
    // EX, RT, then the settings: the state after power-on or an RS report.
    uint8_t initialize(const SensorSettings &settings);
    // Read-modify-write of registers 0x00 (GAIN_SEL, HALLCONF) and 0x02 (RES_XYZ,
    // DIG_FILT, OSR, OSR2); the reserved bits keep their trimmed values.
    uint8_t write_settings(const SensorSettings &settings);
    // SM with the zyxt mask; starts one conversion.
    uint8_t start_single(uint8_t zyxt);
    // RM with the same mask; fills x, y, z and, when the mask has T, temperature.
    uint8_t read_measurement(uint8_t zyxt, ChipReading *reading);

  private:
    uint8_t transfer(const uint8_t *command, uint8_t command_length, uint8_t *response,
                     uint8_t response_length);

    uint8_t address_;
};

}  // namespace softtip

#endif
