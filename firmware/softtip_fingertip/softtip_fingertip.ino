// softtip fingertip firmware: reads up to eight MLX90393 chips synchronously and
// streams one binary frame per acquisition over the serial port; answers the
// host's commands (identify, configure, start, stop, set rate). The protocol is
// described in ../PROTOCOL.md.
//
// Boards: Uno-class (ATmega328P, serial through a USB bridge at 1,000,000 baud)
// and native-USB boards (ATmega32U4, SAMD, ...: the baud rate is ignored).
// I2C runs at 400 kHz.
#include <Wire.h>

#include "mlx90393.h"
#include "protocol.h"

using namespace softtip;

// ---------------------------------------------------------------------------
// Build configuration: override with -D on the compiler command line.
// ---------------------------------------------------------------------------
// SOFTTIP_USE_MUX 1: chip i sits on channel i of a TCA9548A at 0x70, every chip at
// 0x0C. SOFTTIP_USE_MUX 0: the chips share the bus at the addresses of
// DIRECT_ADDRESSES (set by their A1/A0 pins and part variant: edit to match).
#ifndef SOFTTIP_CHIP_COUNT
#define SOFTTIP_CHIP_COUNT 4
#endif
#ifndef SOFTTIP_USE_MUX
#define SOFTTIP_USE_MUX 1
#endif

const uint8_t CHIP_COUNT = SOFTTIP_CHIP_COUNT;
static_assert(SOFTTIP_CHIP_COUNT >= 1 && SOFTTIP_CHIP_COUNT <= 8, "SOFTTIP_CHIP_COUNT: 1..8");
const uint32_t SERIAL_BAUD = 1000000;
const uint32_t I2C_CLOCK_HZ = 400000;
const uint32_t I2C_TIMEOUT_US = 3000;  // a stuck bus (unplugged chip) must not hang the loop
const uint16_t DEFAULT_RATE_HZ = 50;
const uint8_t MUX_ADDRESS = 0x70;
const uint8_t MLX_MUX_ADDRESS = 0x0C;
const uint8_t DIRECT_ADDRESSES[MAX_CHIPS] = {0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13};
const uint8_t NO_CHANNEL = 0xFF;

#if defined(WIRE_HAS_TIMEOUT) || defined(ARDUINO_ARCH_AVR)  // AVR core >= 1.8.3
#define SOFTTIP_WIRE_TIMEOUT 1
#else
#define SOFTTIP_WIRE_TIMEOUT 0
#endif

#if SOFTTIP_USE_MUX
#define SOFTTIP_BUS_NAME "mux"
#else
#define SOFTTIP_BUS_NAME "direct"
#endif
#if defined(USBCON)
#define SOFTTIP_LINK_NAME "usb"
#else
#define SOFTTIP_LINK_NAME "uart"
#endif
const char DEVICE_NAME[] = "softtip-fingertip/1 " SOFTTIP_BUS_NAME " " SOFTTIP_LINK_NAME;

// ---------------------------------------------------------------------------
// State
// ---------------------------------------------------------------------------
Mlx90393 chips[CHIP_COUNT];
bool chip_needs_init[CHIP_COUNT];
uint32_t trigger_us[CHIP_COUNT];
ChipReading readings[CHIP_COUNT];
SensorSettings settings;
uint32_t conversion_wait_us;
uint32_t frame_period_us;
uint32_t next_frame_us;
bool streaming = false;
uint16_t seq = 0;
uint8_t boot_frames_left = BOOT_FRAMES;
uint8_t selected_channel = NO_CHANNEL;
CommandParser parser;
uint8_t out[MAX_DATA_FRAME];

// ---------------------------------------------------------------------------
// Bus
// ---------------------------------------------------------------------------

// A transfer of this frame timed out (SDA or SCL held low): the frame's remaining transfers are
// skipped, so a stuck bus costs one timeout per frame instead of one per transfer, and the stream
// keeps its rate with every chip flagged BUS_ERROR.
bool bus_timed_out() {
#if SOFTTIP_WIRE_TIMEOUT
    return Wire.getWireTimeoutFlag();
#else
    return false;
#endif
}

void clear_bus_timeout() {
#if SOFTTIP_WIRE_TIMEOUT
    Wire.clearWireTimeoutFlag();
#endif
}

// Route the bus to chip i; false when the multiplexer does not acknowledge.
bool select_chip(uint8_t i) {
#if SOFTTIP_USE_MUX
    if (selected_channel == i) return true;
    Wire.beginTransmission(MUX_ADDRESS);
    Wire.write(static_cast<uint8_t>(1 << i));
    if (Wire.endTransmission() != 0) {
        selected_channel = NO_CHANNEL;
        return false;
    }
    selected_channel = i;
#else
    (void)i;
#endif
    return true;
}

void update_conversion_wait() {
    // Table 8 gives typical timings; 10 % margin for the on-chip oscillator.
    const uint32_t conversion = conversion_time_us(settings);
    conversion_wait_us = conversion + conversion / 10;
}

void initialize_chip(uint8_t i) {
    if (!select_chip(i)) {
        chip_needs_init[i] = true;
        return;
    }
    const uint8_t faults = chips[i].initialize(settings);
    chip_needs_init[i] = (faults & (CHIP_BUS_ERROR | CHIP_ERROR)) != 0;
}

// Write the settings to every chip; returns a mask of the chips that refused them.
uint8_t configure_all() {
    uint8_t failed = 0;
    for (uint8_t i = 0; i < CHIP_COUNT; ++i) {
        uint8_t faults = CHIP_BUS_ERROR;
        if (select_chip(i)) {
            faults = chip_needs_init[i] ? chips[i].initialize(settings)
                                        : chips[i].write_settings(settings);
        }
        chip_needs_init[i] = (faults & (CHIP_BUS_ERROR | CHIP_ERROR)) != 0;
        if (chip_needs_init[i]) failed |= static_cast<uint8_t>(1 << i);
    }
    return failed;
}

// ---------------------------------------------------------------------------
// Acquisition
// ---------------------------------------------------------------------------

// Trigger every chip (SM), then read each (RM) once its own conversion is done.
void acquire_frame() {
    const uint8_t zyxt = static_cast<uint8_t>(MLX_AXES_XYZ | (settings.temperature ? MLX_AXIS_T : 0));
    const uint32_t frame_time_us = micros();
    clear_bus_timeout();
    for (uint8_t i = 0; i < CHIP_COUNT; ++i) {
        ChipReading &reading = readings[i];
        reading.x = reading.y = reading.z = reading.temperature = 0;
        const bool reachable = !bus_timed_out() && select_chip(i);
        reading.status = reachable ? chips[i].start_single(zyxt) : static_cast<uint8_t>(CHIP_BUS_ERROR);
        trigger_us[i] = micros();
    }
    for (uint8_t i = 0; i < CHIP_COUNT; ++i) {
        ChipReading &reading = readings[i];
        if (reading.status & CHIP_FAULTS) continue;
        if (bus_timed_out() || !select_chip(i)) {
            reading.status |= CHIP_BUS_ERROR;
            continue;
        }
        while (micros() - trigger_us[i] < conversion_wait_us) {
        }
        reading.status |= chips[i].read_measurement(zyxt, &reading);
        if (reading.status & CHIP_BUS_ERROR) {
            reading.x = reading.y = reading.z = reading.temperature = 0;
        }
    }
    uint8_t flags = settings.temperature ? DATA_TEMPERATURE : 0;
    if (boot_frames_left > 0) {
        flags |= DATA_BOOT;
        --boot_frames_left;
    }
    Serial.write(out, encode_data(out, seq, frame_time_us, flags, readings, CHIP_COUNT));
    ++seq;
    // ERROR too: a chip left in burst or wake-up-on-change mode refuses SM until EX, and after an
    // uncorrectable memory error it accepts nothing but RT (datasheet, "Status byte")
    for (uint8_t i = 0; i < CHIP_COUNT; ++i) {
        if (readings[i].status & (CHIP_RESET | CHIP_BUS_ERROR | CHIP_ERROR)) chip_needs_init[i] = true;
    }
}

// ---------------------------------------------------------------------------
// Host commands
// ---------------------------------------------------------------------------

void reply_error(uint8_t code, uint8_t detail) {
    Serial.write(out, encode_error(out, parser.type(), parser.tag(), code, detail));
}

void reply_ack() { Serial.write(out, encode_ack(out, parser.type(), parser.tag())); }

void handle_command() {
    const uint8_t type = parser.type();
    const bool no_args = parser.args_length() == 0;
    switch (type) {
        case CMD_IDENTIFY:
            if (!no_args) return reply_error(ERROR_BAD_LENGTH, 0);
            Serial.write(out, encode_identity(out, parser.tag(), CHIP_COUNT, DEVICE_NAME));
            return;
        case CMD_CONFIGURE: {
            SensorSettings requested;
            const uint8_t code = decode_settings(parser.args(), parser.args_length(), &requested);
            if (code) return reply_error(code, 0);
            settings = requested;
            update_conversion_wait();
            const uint8_t failed = configure_all();
            if (failed) return reply_error(ERROR_CHIP_FAILURE, failed);
            return reply_ack();
        }
        case CMD_START:
            if (!no_args) return reply_error(ERROR_BAD_LENGTH, 0);
            if (!streaming) next_frame_us = micros();
            streaming = true;
            return reply_ack();
        case CMD_STOP:
            if (!no_args) return reply_error(ERROR_BAD_LENGTH, 0);
            streaming = false;
            return reply_ack();
        case CMD_SET_RATE: {
            uint16_t rate_hz = 0;
            const uint8_t code = decode_rate(parser.args(), parser.args_length(), &rate_hz);
            if (code) return reply_error(code, 0);
            frame_period_us = 1000000UL / rate_hz;
            return reply_ack();
        }
        default:
            return reply_error(ERROR_UNKNOWN_COMMAND, 0);
    }
}

void service_commands() {
    while (Serial.available() > 0) {
        parser.feed(static_cast<uint8_t>(Serial.read()));
        while (parser.next()) handle_command();
    }
}

// ---------------------------------------------------------------------------

void setup() {
    Serial.begin(SERIAL_BAUD);
    Wire.begin();
    Wire.setClock(I2C_CLOCK_HZ);
#if SOFTTIP_WIRE_TIMEOUT
    Wire.setWireTimeout(I2C_TIMEOUT_US, true);
#endif
    settings = default_settings();
    update_conversion_wait();
    frame_period_us = 1000000UL / DEFAULT_RATE_HZ;
    for (uint8_t i = 0; i < CHIP_COUNT; ++i) {
#if SOFTTIP_USE_MUX
        chips[i] = Mlx90393(MLX_MUX_ADDRESS);
#else
        chips[i] = Mlx90393(DIRECT_ADDRESSES[i]);
#endif
        initialize_chip(i);
    }
}

void loop() {
    service_commands();
    if (!streaming) return;
    if (static_cast<int32_t>(micros() - next_frame_us) < 0) return;
    acquire_frame();
    next_frame_us += frame_period_us;
    // Behind schedule (period shorter than an acquisition, or a stall): restart the
    // schedule from now instead of sending a burst of late frames.
    if (static_cast<int32_t>(micros() - next_frame_us) > 0) next_frame_us = micros();
    // a bus that timed out is retried by the next frame, not by every chip's initialisation
    for (uint8_t i = 0; i < CHIP_COUNT && !bus_timed_out(); ++i) {
        if (chip_needs_init[i]) initialize_chip(i);
    }
}
