#include "mlx90393.h"

namespace softtip {

namespace {

// Register map (datasheet, "Volatile memory map").
const uint8_t REG_GAIN_HALLCONF = 0x00;  // [3:0] HALLCONF, [6:4] GAIN_SEL
const uint8_t REG_RES_FILTER = 0x02;     // [1:0] OSR, [4:2] DIG_FILT, [6:5] RES_X,
                                         // [8:7] RES_Y, [10:9] RES_Z, [12:11] OSR2
const uint16_t GAIN_HALLCONF_MASK = 0x007F;
const uint16_t RES_FILTER_MASK = 0x1FFF;
// RT re-reads the trimming from non-volatile memory; the datasheet gives no figure
// for how long that takes, so the wait is generous (it only happens at start-up).
const uint16_t RESET_WAIT_MS = 5;

uint8_t status_faults(uint8_t status) {
    uint8_t faults = 0;
    if (status & MLX_STATUS_ERROR) faults |= CHIP_ERROR;
    if (status & MLX_STATUS_SED) faults |= CHIP_SED;
    return faults;
}

uint16_t word_at(const uint8_t *bytes) {
    return static_cast<uint16_t>((bytes[0] << 8) | bytes[1]);
}

}  // namespace

uint8_t Mlx90393::transfer(const uint8_t *command, uint8_t command_length, uint8_t *response,
                           uint8_t response_length) {
    Wire.beginTransmission(address_);
    Wire.write(command, command_length);
    // Repeated start: the read of the response follows without a stop condition.
    if (Wire.endTransmission(false) != 0) {
        return CHIP_BUS_ERROR;
    }
    if (Wire.requestFrom(address_, response_length) != response_length) {
        return CHIP_BUS_ERROR;
    }
    for (uint8_t i = 0; i < response_length; ++i) {
        response[i] = static_cast<uint8_t>(Wire.read());
    }
    return 0;
}

uint8_t Mlx90393::exit_mode() {
    const uint8_t command = MLX_CMD_EX;
    uint8_t status = 0;
    const uint8_t bus = transfer(&command, 1, &status, 1);
    return bus ? bus : status_faults(status);
}

uint8_t Mlx90393::reset() {
    const uint8_t command = MLX_CMD_RT;
    uint8_t status = 0;
    const uint8_t bus = transfer(&command, 1, &status, 1);
    // RS is expected here: it reports the reset just requested.
    return bus ? bus : status_faults(status);
}

uint8_t Mlx90393::read_register(uint8_t reg, uint16_t *value) {
    const uint8_t command[2] = {MLX_CMD_RR, static_cast<uint8_t>(reg << 2)};
    uint8_t response[3];
    const uint8_t bus = transfer(command, sizeof command, response, sizeof response);
    if (bus) return bus;
    *value = word_at(response + 1);
    return status_faults(response[0]);
}

uint8_t Mlx90393::write_register(uint8_t reg, uint16_t value) {
    const uint8_t command[4] = {MLX_CMD_WR, static_cast<uint8_t>(value >> 8),
                                static_cast<uint8_t>(value), static_cast<uint8_t>(reg << 2)};
    uint8_t status = 0;
    const uint8_t bus = transfer(command, sizeof command, &status, 1);
    return bus ? bus : status_faults(status);
}

uint8_t Mlx90393::initialize(const SensorSettings &settings) {
    // EX first: a chip left in burst or wake-up-on-change mode ignores RT otherwise.
    uint8_t faults = exit_mode();
    if (faults & CHIP_BUS_ERROR) return faults;
    faults = reset();
    if (faults & CHIP_BUS_ERROR) return faults;
    delay(RESET_WAIT_MS);
    return write_settings(settings);
}

uint8_t Mlx90393::write_settings(const SensorSettings &settings) {
    uint16_t gain_hallconf = 0;
    uint8_t faults = read_register(REG_GAIN_HALLCONF, &gain_hallconf);
    if (faults & (CHIP_BUS_ERROR | CHIP_ERROR)) return faults;
    gain_hallconf = static_cast<uint16_t>((gain_hallconf & ~GAIN_HALLCONF_MASK) |
                                          (settings.gain_sel << 4) | settings.hallconf);
    faults |= write_register(REG_GAIN_HALLCONF, gain_hallconf);
    if (faults & (CHIP_BUS_ERROR | CHIP_ERROR)) return faults;

    uint16_t res_filter = 0;
    faults |= read_register(REG_RES_FILTER, &res_filter);
    if (faults & (CHIP_BUS_ERROR | CHIP_ERROR)) return faults;
    const uint16_t fields = static_cast<uint16_t>(
        settings.osr | (settings.dig_filt << 2) | (settings.res_x << 5) |
        (settings.res_y << 7) | (settings.res_z << 9) | (settings.osr2 << 11));
    res_filter = static_cast<uint16_t>((res_filter & ~RES_FILTER_MASK) | fields);
    return faults | write_register(REG_RES_FILTER, res_filter);
}

uint8_t Mlx90393::start_single(uint8_t zyxt) {
    const uint8_t command = static_cast<uint8_t>(MLX_CMD_SM | zyxt);
    uint8_t status = 0;
    const uint8_t bus = transfer(&command, 1, &status, 1);
    if (bus) return bus;
    uint8_t faults = status_faults(status);
    // RS outside our own RT means the chip restarted (supply dip) with power-on registers.
    if (status & MLX_STATUS_RS) faults |= CHIP_RESET;
    return faults;
}

uint8_t Mlx90393::read_measurement(uint8_t zyxt, ChipReading *reading) {
    const uint8_t with_temperature = zyxt & MLX_AXIS_T;
    const uint8_t words = with_temperature ? 4 : 3;
    const uint8_t command = static_cast<uint8_t>(MLX_CMD_RM | zyxt);
    uint8_t response[1 + 2 * 4];
    const uint8_t bus = transfer(&command, 1, response, static_cast<uint8_t>(1 + 2 * words));
    if (bus) return bus;
    const uint8_t status = response[0];
    uint8_t faults = status_faults(status);
    if (status & MLX_STATUS_RS) faults |= CHIP_RESET;
    if ((status & MLX_STATUS_D) != words - 1) faults |= CHIP_COUNT_MISMATCH;
    // The chip sends T (when selected) before X, Y, Z.
    const uint8_t *data = response + 1;
    if (with_temperature) {
        reading->temperature = word_at(data);
        data += 2;
    }
    reading->x = word_at(data);
    reading->y = word_at(data + 2);
    reading->z = word_at(data + 4);
    return faults;
}

}  // namespace softtip
