// Serial protocol of the softtip fingertip: frame encoding, CRC, command parsing and
// the sensor settings carried by the CONFIGURE command. Layout: ../PROTOCOL.md.
//
// Plain C++11 with no Arduino dependency: the same unit is compiled into the sketch
// and into the host test program (test/frame_test.cpp).
#ifndef SOFTTIP_PROTOCOL_H
#define SOFTTIP_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

namespace softtip {

const uint8_t SYNC_0 = 0xA5;
const uint8_t SYNC_1 = 0x5A;
const uint8_t PROTOCOL_VERSION = 1;
const uint8_t HEADER_SIZE = 5;  // sync (2), version, type, payload length
const uint8_t CRC_SIZE = 2;
const uint8_t MAX_CHIPS = 8;
const uint8_t DATA_HEADER_SIZE = 8;  // seq (2), device time (4), chip count, flags
const uint8_t CHIP_BLOCK_SIZE = 7;   // status, x, y, z
const uint8_t CHIP_BLOCK_WITH_TEMPERATURE_SIZE = 9;
const uint8_t MAX_DATA_PAYLOAD = DATA_HEADER_SIZE + MAX_CHIPS * CHIP_BLOCK_WITH_TEMPERATURE_SIZE;
const uint8_t MAX_NAME_LENGTH = 48;
const uint8_t MAX_COMMAND_PAYLOAD = 16;  // tag + up to 15 argument bytes
const uint8_t MAX_DATA_FRAME = HEADER_SIZE + MAX_DATA_PAYLOAD + CRC_SIZE;
const uint8_t MAX_COMMAND_FRAME = HEADER_SIZE + MAX_COMMAND_PAYLOAD + CRC_SIZE;
const uint8_t BOOT_FRAMES = 8;  // data frames after power-on that carry DATA_BOOT
const uint16_t MIN_RATE_HZ = 1;
const uint16_t MAX_RATE_HZ = 1000;

enum FrameType {
    FRAME_DATA = 0x01,
    FRAME_IDENTITY = 0x02,
    FRAME_ACK = 0x03,
    FRAME_ERROR = 0x04,
    FIRST_COMMAND = 0x10,
    CMD_IDENTIFY = 0x10,
    CMD_CONFIGURE = 0x11,
    CMD_START = 0x12,
    CMD_STOP = 0x13,
    CMD_SET_RATE = 0x14,
    LAST_COMMAND = 0x1F
};

enum ErrorCode {
    ERROR_UNKNOWN_COMMAND = 1,
    ERROR_BAD_LENGTH = 2,
    ERROR_BAD_SETTINGS = 3,
    ERROR_BAD_RATE = 4,
    ERROR_CHIP_FAILURE = 5  // detail byte: bit i set when chip i did not accept the settings
};

enum DataFlag {
    DATA_TEMPERATURE = 0x01,  // each chip block carries a raw temperature word
    DATA_BOOT = 0x02          // one of the first BOOT_FRAMES frames since power-on
};

// Per-chip status byte of a data frame, composed by the firmware from the bus
// transfers and the chip's own status bytes.
enum ChipStatus {
    CHIP_BUS_ERROR = 0x01,       // no acknowledge or short read; the words are 0
    CHIP_ERROR = 0x02,           // ERROR bit in the SM or RM status byte
    CHIP_RESET = 0x04,           // RS bit: the chip was reset and lost its settings
    CHIP_COUNT_MISMATCH = 0x08,  // RM status D1:D0 disagrees with the words requested
    CHIP_SED = 0x10              // SED bit: a memory bit error was detected (informational)
};
const uint8_t CHIP_FAULTS = CHIP_BUS_ERROR | CHIP_ERROR | CHIP_RESET | CHIP_COUNT_MISMATCH;

struct ChipReading {
    uint8_t status;
    uint16_t x;
    uint16_t y;
    uint16_t z;
    uint16_t temperature;
};

// Register settings of every chip, in the order of the CONFIGURE arguments.
struct SensorSettings {
    uint8_t gain_sel;
    uint8_t res_x;
    uint8_t res_y;
    uint8_t res_z;
    uint8_t osr;
    uint8_t dig_filt;
    uint8_t osr2;
    uint8_t hallconf;
    uint8_t temperature;
};
const uint8_t SETTINGS_ARGS = 9;

// Power-on registers except DIG_FILT, whose power-on value 0 is forbidden with OSR 0.
SensorSettings default_settings();

// CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR.
uint16_t crc16(const uint8_t *data, size_t length);

// Each encoder writes one complete frame to out and returns its length in bytes.
size_t encode_frame(uint8_t *out, uint8_t type, const uint8_t *payload, uint8_t length);
size_t encode_data(uint8_t *out, uint16_t seq, uint32_t device_time_us, uint8_t flags,
                   const ChipReading *chips, uint8_t count);
size_t encode_identity(uint8_t *out, uint8_t tag, uint8_t chips, const char *name);
size_t encode_ack(uint8_t *out, uint8_t command, uint8_t tag);
size_t encode_error(uint8_t *out, uint8_t command, uint8_t tag, uint8_t code, uint8_t detail);

// Validate CONFIGURE / SET_RATE arguments; return 0 or the ErrorCode to reply with.
uint8_t decode_settings(const uint8_t *args, uint8_t length, SensorSettings *settings);
uint8_t decode_rate(const uint8_t *args, uint8_t length, uint16_t *rate_hz);

// Single-measurement conversion time in microseconds (datasheet Table 8) for the
// three magnetic axes, plus the temperature when settings.temperature is set.
uint32_t conversion_time_us(const SensorSettings &settings);

// Streaming parser for host commands: resynchronises on garbage and drops frames
// with a bad CRC. Call next() after every feed(); while it returns true a command
// is available through type(), tag(), args() and args_length().
class CommandParser {
  public:
    CommandParser();
    void feed(uint8_t byte);
    bool next();
    uint8_t type() const { return buffer_[3]; }
    uint8_t tag() const { return buffer_[HEADER_SIZE]; }
    const uint8_t *args() const { return buffer_ + HEADER_SIZE + 1; }
    uint8_t args_length() const { return buffer_[4] - 1; }
    uint32_t crc_errors() const { return crc_errors_; }
    uint32_t bytes_discarded() const { return bytes_discarded_; }

  private:
    enum Scan { SCAN_INCOMPLETE, SCAN_INVALID, SCAN_COMPLETE };
    Scan scan();
    void drop_front(uint8_t count);

    uint8_t buffer_[MAX_COMMAND_FRAME];
    uint8_t size_;
    uint8_t delivered_;  // length of the frame handed out by the last next(), 0 if none
    uint32_t crc_errors_;
    uint32_t bytes_discarded_;
};

}  // namespace softtip

#endif
