#include "protocol.h"

#include <string.h>

namespace softtip {

namespace {

void put_u16(uint8_t *out, uint16_t value) {
    out[0] = static_cast<uint8_t>(value);
    out[1] = static_cast<uint8_t>(value >> 8);
}

void put_u32(uint8_t *out, uint32_t value) {
    put_u16(out, static_cast<uint16_t>(value));
    put_u16(out + 2, static_cast<uint16_t>(value >> 16));
}

// Datasheet Table 8 timings in microseconds.
const uint32_t STANDBY_US = 264;
const uint32_t ACTIVE_US = 432;
const uint32_t CONVERSION_END_US = 120;
const uint32_t AXIS_FIXED_US = 67;
const uint32_t AXIS_SAMPLE_US = 64;
const uint32_t TEMPERATURE_FIXED_US = 67;
const uint32_t TEMPERATURE_SAMPLE_US = 192;

}  // namespace

SensorSettings default_settings() {
    SensorSettings settings;
    settings.gain_sel = 7;
    settings.res_x = 0;
    settings.res_y = 0;
    settings.res_z = 0;
    settings.osr = 0;
    settings.dig_filt = 2;
    settings.osr2 = 0;
    settings.hallconf = 0x0C;
    settings.temperature = 0;
    return settings;
}

uint16_t crc16(const uint8_t *data, size_t length) {
    // Byte-wise form of the MSB-first shift register with polynomial 0x1021: the
    // same result as eight single-bit steps, in a few shifts and XORs per byte.
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < length; ++i) {
        crc = static_cast<uint16_t>((crc >> 8) | (crc << 8));
        crc ^= data[i];
        crc ^= static_cast<uint16_t>((crc & 0xFF) >> 4);
        crc ^= static_cast<uint16_t>(crc << 12);
        crc ^= static_cast<uint16_t>((crc & 0xFF) << 5);
    }
    return crc;
}

size_t encode_frame(uint8_t *out, uint8_t type, const uint8_t *payload, uint8_t length) {
    out[0] = SYNC_0;
    out[1] = SYNC_1;
    out[2] = PROTOCOL_VERSION;
    out[3] = type;
    out[4] = length;
    memmove(out + HEADER_SIZE, payload, length);
    // The CRC covers version, type, length and payload: everything after the sync bytes.
    put_u16(out + HEADER_SIZE + length, crc16(out + 2, HEADER_SIZE - 2 + length));
    return HEADER_SIZE + length + CRC_SIZE;
}

size_t encode_data(uint8_t *out, uint16_t seq, uint32_t device_time_us, uint8_t flags,
                   const ChipReading *chips, uint8_t count) {
    // The payload is assembled in place, after the header, and encode_frame's
    // memmove onto itself is a no-op copy.
    uint8_t *payload = out + HEADER_SIZE;
    put_u16(payload, seq);
    put_u32(payload + 2, device_time_us);
    payload[6] = count;
    payload[7] = flags;
    uint8_t *block = payload + DATA_HEADER_SIZE;
    for (uint8_t i = 0; i < count; ++i) {
        block[0] = chips[i].status;
        put_u16(block + 1, chips[i].x);
        put_u16(block + 3, chips[i].y);
        put_u16(block + 5, chips[i].z);
        block += CHIP_BLOCK_SIZE;
        if (flags & DATA_TEMPERATURE) {
            put_u16(block, chips[i].temperature);
            block += 2;
        }
    }
    return encode_frame(out, FRAME_DATA, payload, static_cast<uint8_t>(block - payload));
}

size_t encode_identity(uint8_t *out, uint8_t tag, uint8_t chips, const char *name) {
    uint8_t payload[2 + MAX_NAME_LENGTH];
    payload[0] = tag;
    payload[1] = chips;
    uint8_t length = 0;
    while (name[length] != '\0' && length < MAX_NAME_LENGTH) {
        payload[2 + length] = static_cast<uint8_t>(name[length]);
        ++length;
    }
    return encode_frame(out, FRAME_IDENTITY, payload, static_cast<uint8_t>(2 + length));
}

size_t encode_ack(uint8_t *out, uint8_t command, uint8_t tag) {
    const uint8_t payload[2] = {command, tag};
    return encode_frame(out, FRAME_ACK, payload, sizeof payload);
}

size_t encode_error(uint8_t *out, uint8_t command, uint8_t tag, uint8_t code, uint8_t detail) {
    const uint8_t payload[4] = {command, tag, code, detail};
    return encode_frame(out, FRAME_ERROR, payload, sizeof payload);
}

uint8_t decode_settings(const uint8_t *args, uint8_t length, SensorSettings *settings) {
    if (length != SETTINGS_ARGS) {
        return ERROR_BAD_LENGTH;
    }
    SensorSettings s;
    s.gain_sel = args[0];
    s.res_x = args[1];
    s.res_y = args[2];
    s.res_z = args[3];
    s.osr = args[4];
    s.dig_filt = args[5];
    s.osr2 = args[6];
    s.hallconf = args[7];
    s.temperature = args[8];
    const bool in_range = s.gain_sel <= 7 && s.res_x <= 3 && s.res_y <= 3 && s.res_z <= 3 &&
                          s.osr <= 3 && s.dig_filt <= 7 && s.osr2 <= 3 &&
                          (s.hallconf == 0x0C || s.hallconf == 0x00) && s.temperature <= 1;
    // Datasheet: OSR 0 needs DIG_FILT >= 2 and OSR 1 needs DIG_FILT >= 1.
    const bool permitted = !(s.osr == 0 && s.dig_filt < 2) && !(s.osr == 1 && s.dig_filt < 1);
    if (!in_range || !permitted) {
        return ERROR_BAD_SETTINGS;
    }
    *settings = s;
    return 0;
}

uint8_t decode_rate(const uint8_t *args, uint8_t length, uint16_t *rate_hz) {
    if (length != 2) {
        return ERROR_BAD_LENGTH;
    }
    const uint16_t rate = static_cast<uint16_t>(args[0] | (args[1] << 8));
    if (rate < MIN_RATE_HZ || rate > MAX_RATE_HZ) {
        return ERROR_BAD_RATE;
    }
    *rate_hz = rate;
    return 0;
}

uint32_t conversion_time_us(const SensorSettings &settings) {
    const uint32_t averaging = (1UL << settings.osr) * (2UL + (1UL << settings.dig_filt));
    uint32_t total = STANDBY_US + ACTIVE_US + CONVERSION_END_US +
                     3 * (AXIS_FIXED_US + AXIS_SAMPLE_US * averaging);
    if (settings.temperature) {
        total += TEMPERATURE_FIXED_US + TEMPERATURE_SAMPLE_US * (1UL << settings.osr2);
    }
    return total;
}

CommandParser::CommandParser() : size_(0), delivered_(0), crc_errors_(0), bytes_discarded_(0) {}

void CommandParser::feed(uint8_t byte) {
    if (delivered_) {
        drop_front(delivered_);
        delivered_ = 0;
    }
    if (size_ == sizeof buffer_) {
        // Only reachable when next() is not called after each feed().
        ++bytes_discarded_;
        return;
    }
    buffer_[size_++] = byte;
}

bool CommandParser::next() {
    if (delivered_) {
        drop_front(delivered_);
        delivered_ = 0;
    }
    while (size_ > 0) {
        const Scan scan_result = scan();
        if (scan_result == SCAN_INCOMPLETE) {
            return false;
        }
        if (scan_result == SCAN_COMPLETE) {
            delivered_ = static_cast<uint8_t>(HEADER_SIZE + buffer_[4] + CRC_SIZE);
            return true;
        }
        // Not a frame start: drop one byte and look for the next sync.
        drop_front(1);
        ++bytes_discarded_;
    }
    return false;
}

CommandParser::Scan CommandParser::scan() {
    if (buffer_[0] != SYNC_0) return SCAN_INVALID;
    if (size_ < 2) return SCAN_INCOMPLETE;
    if (buffer_[1] != SYNC_1) return SCAN_INVALID;
    if (size_ < 3) return SCAN_INCOMPLETE;
    if (buffer_[2] != PROTOCOL_VERSION) return SCAN_INVALID;
    if (size_ < 4) return SCAN_INCOMPLETE;
    if (buffer_[3] < FIRST_COMMAND || buffer_[3] > LAST_COMMAND) return SCAN_INVALID;
    if (size_ < 5) return SCAN_INCOMPLETE;
    const uint8_t length = buffer_[4];
    if (length < 1 || length > MAX_COMMAND_PAYLOAD) return SCAN_INVALID;
    const uint8_t frame_size = static_cast<uint8_t>(HEADER_SIZE + length + CRC_SIZE);
    if (size_ < frame_size) return SCAN_INCOMPLETE;
    const uint16_t received = static_cast<uint16_t>(buffer_[frame_size - 2] |
                                                    (buffer_[frame_size - 1] << 8));
    if (crc16(buffer_ + 2, HEADER_SIZE - 2 + length) != received) {
        ++crc_errors_;
        return SCAN_INVALID;
    }
    return SCAN_COMPLETE;
}

void CommandParser::drop_front(uint8_t count) {
    memmove(buffer_, buffer_ + count, size_ - count);
    size_ = static_cast<uint8_t>(size_ - count);
}

}  // namespace softtip
