// The fingertip firmware's build (its ELF for the ATmega328P) executed in simavr, with the I2C parts
// of the fingertip emulated on the AVR's TWI: a TCA9548A multiplexer at 0x70 and one MLX90393 at 0x0C
// behind each of its channels, answering the datasheet's command set with fields read from a file or
// a pipe. The AVR's UART is a pseudo-terminal the host opens like the board's serial port.
//
//   fingertip_sim FIRMWARE.elf --chips N --fields PATH [--link PATH] [--temperature-c T]
//
// --fields: text, one row per conversion, 3 * N numbers (x, y, z in uT of chip 0, then chip 1, ...);
// '#' starts a comment. A regular file is read whole and its rows used in turn, cycling: the k-th
// conversion of every chip (that is the frame of sequence number k) takes row k mod rows. A FIFO is
// read as rows arrive: the k-th conversion takes row k if it has arrived, else the latest row (a zero
// field before the first).
// The simulation is paced to the wall clock (simulated time never runs ahead of real time).
//
// Standard input takes control lines: "nak CHIP 0|1" (the chip stops / resumes acknowledging its
// address), "stuck 0|1" (SDA held low: no START completes), "reset CHIP" (the chip restarts with
// power-on registers, as after a supply dip), "burst CHIP" (the chip is left in burst mode), "regs"
// (print every chip's registers 0x00 and 0x02), "time", "quit". Standard output carries one event
// per line:
//   pty PATH                         the serial port to open
//   conv CHIP K SIM_NS WALL_NS X Y Z  chip's K-th conversion ended (simulated time, CLOCK_MONOTONIC)
//   frame SEQ SIM_NS WALL_NS          a DATA frame's last bit left the UART; its bytes went to the pty
//   early CHIP SIM_NS                 RM before the conversion ended (ERROR, with the previous data)
//   regs CHIP REG0 REG2               answer to "regs" (hexadecimal)
//   time SIM_NS WALL_NS               every 10 ms of simulated time, on "time", and at exit
// Written from the MLX90393 datasheet (Melexis, rev. 006), the TCA9548A datasheet (Texas Instruments)
// and simavr's TWI model; simavr 1.6 times one bus clock as 1 us whatever TWBR says, and a START, a
// STOP and a write's address byte as none: here they take the clock the firmware set (400 kHz: 2.5 us).
#define _GNU_SOURCE
#include <fcntl.h>
#include <math.h>
#include <pty.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <avr_twi.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_io.h>
#include <sim_time.h>

#define MAX_CHIPS 8
#define MUX_ADDRESS 0x70
#define MLX_ADDRESS 0x0C
#define TWCR_ADDRESS 0xBC  // ATmega328P
#define TWBR_ADDRESS 0xB8
#define TWSR_ADDRESS 0xB9
#define TWSTA_BIT 5
#define TWSTO_BIT 4
#define POLL_CYCLES 1600  // 100 us at 16 MHz: serial and control are serviced this often
#define REPORT_CYCLES 160000  // 10 ms: the simulated time is reported this often

// MLX90393 status byte and commands (datasheet, "Command list" and "Status byte").
enum {
    STATUS_BURST = 0x80, STATUS_WOC = 0x40, STATUS_SM = 0x20, STATUS_ERROR = 0x10, STATUS_SED = 0x08,
    STATUS_RS = 0x04,
};
enum { CMD_SB = 0x1, CMD_SW = 0x2, CMD_SM = 0x3, CMD_RM = 0x4, CMD_RR = 0x5, CMD_WR = 0x6, CMD_EX = 0x8,
       CMD_HR = 0xD, CMD_HS = 0xE, CMD_RT = 0xF, CMD_NOP = 0x0 };
#define REGISTERS 64
#define POWER_ON_REG0 0x007C  // GAIN_SEL 7, HALLCONF 0xC
#define POWER_ON_REG2 0x0000  // RES 0/0/0, DIG_FILT 0, OSR 0, OSR2 0

// Table 17, sensitivity in uT/LSB for HALLCONF 0xC: rows GAIN_SEL 0..7, (XY, Z) for RES 0..3 as
// printed (the misprinted XY entry of GAIN_SEL 1 / RES 3, 4.840, read as 2 x 2.403). HALLCONF 0x0
// scales it by 98/75 (footnote to the table).
static const double SENSITIVITY[8][8] = {
    {0.751, 1.210, 1.502, 2.420, 3.004, 4.840, 6.009, 9.680},
    {0.601, 0.968, 1.202, 1.936, 2.403, 3.872, 4.806, 7.744},
    {0.451, 0.726, 0.901, 1.452, 1.803, 2.904, 3.605, 5.808},
    {0.376, 0.605, 0.751, 1.210, 1.502, 2.420, 3.004, 4.840},
    {0.300, 0.484, 0.601, 0.968, 1.202, 1.936, 2.403, 3.872},
    {0.250, 0.403, 0.501, 0.807, 1.001, 1.613, 2.003, 3.227},
    {0.200, 0.323, 0.401, 0.645, 0.801, 1.291, 1.602, 2.581},
    {0.150, 0.242, 0.300, 0.484, 0.601, 0.968, 1.202, 1.936},
};
// Table 21: the zero field and the valid range of the output word for RES 0..3.
static const int32_t ZERO_COUNTS[4] = {0, 0, 32768, 16384};
static const int32_t LOWEST_COUNTS[4] = {-32768, -32768, -22000, -11000};
static const int32_t HIGHEST_COUNTS[4] = {32767, 32767, 22000, 11000};
// Table 8 timings in us.
enum { T_STBY = 264, T_ACTIVE = 432, T_CONV_END = 120, T_AXIS = 67, T_SAMPLE = 64, T_TEMP = 67,
       T_TEMP_SAMPLE = 192 };
#define TEMPERATURE_COUNTS_25C 46244
#define TEMPERATURE_COUNTS_PER_K 45.2

typedef struct {
    int index;
    uint16_t reg[REGISTERS];
    uint8_t mode;       // STATUS_BURST, STATUS_WOC or STATUS_SM while a conversion is pending
    int reset_pending;  // RS: reported in the next status byte
    int naks;           // does not acknowledge its address
    uint8_t command[8];
    int command_length;
    uint8_t response[10];
    int response_length, response_read;
    uint8_t zyxt;                 // axes of the last SM
    uint16_t data[4];             // T, X, Y, Z words of the last finished conversion
    uint16_t pending[4];          // of the conversion under way
    avr_cycle_count_t ready_cycle;
    long conversions;
    int has_data;
} mlx_t;

typedef struct {
    double *values;  // rows * 3 * chips
    long rows, capacity;
    int fifo_fd;     // -1 for a regular file
    char partial[4096];
    size_t partial_length;
} fields_t;

#define MAX_PENDING_FRAMES 64

typedef struct {
    uint8_t head[7];  // sync, version, type, length, sequence number
    int got;
} frame_scan_t;

typedef struct {
    uint16_t seq;
    int64_t end_ns;
} pending_frame_t;

typedef struct {
    avr_t *avr;
    int chips;
    mlx_t mlx[MAX_CHIPS];
    uint8_t mux_channels;
    int addressed;  // -2: none, -1: the mux, i: chip i
    int reading;
    int stuck_bus;
    avr_twi_t *twi;
    avr_io_write_t twcr_write;
    avr_irq_t *twi_input;
    fields_t fields;
    double temperature_c;
    int pty;
    uint8_t tx[8192];
    size_t tx_length;
    int uart_ready;
    frame_scan_t scan;
    pending_frame_t frames[MAX_PENDING_FRAMES];
    int frames_pending;
} sim_t;

static sim_t sim;

static int64_t wall_ns(void) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (int64_t)now.tv_sec * 1000000000 + now.tv_nsec;
}

static int64_t sim_ns(avr_cycle_count_t cycle) {
    return (int64_t)(cycle * 1000000000.0 / sim.avr->frequency);
}

static void die(const char *message) {
    fprintf(stderr, "fingertip_sim: %s\n", message);
    exit(2);
}

// ------------------------------------------------------------------ fields

static void add_row_text(fields_t *f, char *line, int chips) {
    char *hash = strchr(line, '#');
    if (hash) *hash = 0;
    double row[3 * MAX_CHIPS];
    int count = 0;
    char *cursor = line, *end;
    while (count < 3 * chips) {
        double value = strtod(cursor, &end);
        if (end == cursor) break;
        row[count++] = value;
        cursor = end;
    }
    while (*cursor && strchr(" \t\r\n,", *cursor)) ++cursor;
    if (count == 0 && *cursor == 0) return;  // blank or comment
    if (count != 3 * chips || *cursor != 0) {
        fprintf(stderr, "fingertip_sim: --fields: row %ld: expected %d numbers (x y z of %d chips)\n",
                f->rows + 1, 3 * chips, chips);
        exit(2);
    }
    if (f->rows == f->capacity) {
        f->capacity = f->capacity ? 2 * f->capacity : 1024;
        f->values = realloc(f->values, sizeof(double) * 3 * chips * f->capacity);
        if (!f->values) die("out of memory for the fields");
    }
    memcpy(f->values + f->rows * 3 * chips, row, sizeof(double) * 3 * chips);
    ++f->rows;
}

static void read_fifo_rows(fields_t *f, int chips) {
    if (f->fifo_fd < 0) return;
    for (;;) {
        ssize_t n = read(f->fifo_fd, f->partial + f->partial_length, sizeof f->partial - 1 - f->partial_length);
        if (n <= 0) return;
        f->partial_length += (size_t)n;
        f->partial[f->partial_length] = 0;
        char *start = f->partial, *newline;
        while ((newline = strchr(start, '\n'))) {
            *newline = 0;
            add_row_text(f, start, chips);
            start = newline + 1;
        }
        f->partial_length = strlen(start);
        memmove(f->partial, start, f->partial_length + 1);
        if (f->partial_length == sizeof f->partial - 1) die("--fields: a row longer than 4 kB");
    }
}

static void open_fields(fields_t *f, const char *path, int chips) {
    struct stat info;
    if (stat(path, &info) != 0) die("--fields: cannot open the file");
    f->fifo_fd = -1;
    if (S_ISFIFO(info.st_mode)) {
        f->fifo_fd = open(path, O_RDONLY | O_NONBLOCK);
        if (f->fifo_fd < 0) die("--fields: cannot open the pipe");
        return;
    }
    FILE *file = fopen(path, "r");
    if (!file) die("--fields: cannot open the file");
    char line[4096];
    while (fgets(line, sizeof line, file)) add_row_text(f, line, chips);
    fclose(file);
    if (f->rows == 0) die("--fields: the file holds no rows");
}

// Field (uT) of chip i at its k-th conversion.
static const double *field_for(int chip, long k) {
    static const double zero[3] = {0, 0, 0};
    fields_t *f = &sim.fields;
    if (f->rows == 0) return zero;
    long row = f->fifo_fd < 0 ? k % f->rows : (k < f->rows ? k : f->rows - 1);
    return f->values + (row * sim.chips + chip) * 3;
}

// ------------------------------------------------------------------ MLX90393

static void mlx_power_on(mlx_t *m) {
    memset(m->reg, 0, sizeof m->reg);
    m->reg[0] = POWER_ON_REG0;
    m->reg[2] = POWER_ON_REG2;
    m->mode = 0;
    m->reset_pending = 1;
    m->has_data = 0;
    memset(m->data, 0, sizeof m->data);
}

static uint16_t quantise(double field_uT, int axis_z, uint16_t reg0, uint16_t reg2, int axis) {
    const int gain = (reg0 >> 4) & 7, hallconf = reg0 & 0xF;
    const int res = (reg2 >> (5 + 2 * axis)) & 3;
    double sensitivity = SENSITIVITY[gain][2 * res + axis_z];
    if (hallconf == 0) sensitivity *= 98.0 / 75.0;
    double counts = nearbyint(field_uT / sensitivity);
    if (counts < LOWEST_COUNTS[res]) counts = LOWEST_COUNTS[res];
    if (counts > HIGHEST_COUNTS[res]) counts = HIGHEST_COUNTS[res];
    return (uint16_t)((int32_t)counts + ZERO_COUNTS[res]);
}

static uint32_t conversion_us(const mlx_t *m, uint8_t zyxt) {
    const int osr = m->reg[2] & 3, dig_filt = (m->reg[2] >> 2) & 7, osr2 = (m->reg[2] >> 11) & 3;
    uint32_t total = T_STBY + T_ACTIVE + T_CONV_END;
    for (int axis = 1; axis <= 3; ++axis)
        if (zyxt & (1 << axis)) total += T_AXIS + T_SAMPLE * (1u << osr) * (2u + (1u << dig_filt));
    if (zyxt & 1) total += T_TEMP + T_TEMP_SAMPLE * (1u << osr2);
    return total;
}

static avr_cycle_count_t conversion_done(avr_t *avr, avr_cycle_count_t when, void *param) {
    mlx_t *m = param;
    memcpy(m->data, m->pending, sizeof m->data);
    m->has_data = 1;
    m->mode &= (uint8_t)~STATUS_SM;
    printf("conv %d %ld %lld %lld %u %u %u\n", m->index, m->conversions - 1, (long long)sim_ns(when),
           (long long)wall_ns(), m->data[1], m->data[2], m->data[3]);
    (void)avr;
    return 0;
}

static void mlx_start_single(mlx_t *m, uint8_t zyxt) {
    const double *field = field_for(m->index, m->conversions);
    for (int axis = 0; axis < 3; ++axis)
        m->pending[1 + axis] = quantise(field[axis], axis == 2, m->reg[0], m->reg[2], axis);
    double t = TEMPERATURE_COUNTS_25C + (sim.temperature_c - 25.0) * TEMPERATURE_COUNTS_PER_K;
    m->pending[0] = (uint16_t)nearbyint(t);
    m->zyxt = zyxt;
    m->mode |= STATUS_SM;
    ++m->conversions;
    const avr_cycle_count_t cycles = avr_usec_to_cycles(sim.avr, conversion_us(m, zyxt));
    m->ready_cycle = sim.avr->cycle + cycles;
    avr_cycle_timer_register(sim.avr, cycles, conversion_done, m);
}

// An all-zero zyxt argument of SB, SW or SM takes BURST_SEL, bits [9:6] of register 0x01.
static uint8_t burst_sel(const mlx_t *m) { return (uint8_t)((m->reg[1] >> 6) & 0xF); }

// Execute the command collected in the write phase; fill the response (status byte first).
static void mlx_execute(mlx_t *m) {
    uint8_t error = 0, d = 0;
    int words = 0;
    uint16_t out[4];
    const uint8_t code = m->command_length ? m->command[0] >> 4 : 0xFF;
    const uint8_t low = m->command_length ? m->command[0] & 0xF : 0;
    switch (code) {
        case CMD_NOP:
            break;
        case CMD_SB:
        case CMD_SW:
        case CMD_SM:
            if (m->mode & (STATUS_BURST | STATUS_WOC | STATUS_SM)) {
                error = STATUS_ERROR;  // a mode is already running: EX first
            } else if ((low ? low : burst_sel(m)) == 0) {
                error = STATUS_ERROR;  // nothing to convert
            } else if (code == CMD_SM) {
                mlx_start_single(m, low ? low : burst_sel(m));
            } else {
                m->mode = code == CMD_SB ? STATUS_BURST : STATUS_WOC;
            }
            break;
        case CMD_RM:
            if (!m->has_data && !(m->mode & STATUS_SM)) {
                error = STATUS_ERROR;
                break;
            }
            if (sim.avr->cycle < m->ready_cycle) {  // DRDY low: the previous data, flagged
                error = STATUS_ERROR;
                printf("early %d %lld\n", m->index, (long long)sim_ns(sim.avr->cycle));
            }
            for (int axis = 0; axis < 4; ++axis)  // T before X, Y, Z
                if (low & (1 << axis)) out[words++] = m->data[axis];
            break;
        case CMD_RR:
            if (m->command_length != 2) {
                error = STATUS_ERROR;
                break;
            }
            out[words++] = m->reg[(m->command[1] >> 2) & (REGISTERS - 1)];
            break;
        case CMD_WR:
            if (m->command_length != 4) {
                error = STATUS_ERROR;
                break;
            }
            m->reg[(m->command[3] >> 2) & (REGISTERS - 1)] = (uint16_t)(m->command[1] << 8 | m->command[2]);
            break;
        case CMD_EX:
            m->mode = 0;
            break;
        case CMD_RT:
            mlx_power_on(m);
            break;
        default:
            error = STATUS_ERROR;
    }
    if (words) d = (uint8_t)(words - 1);
    uint8_t status = (uint8_t)(m->mode | error | d);
    if (m->reset_pending) {
        status |= STATUS_RS;
        m->reset_pending = 0;
    }
    m->response[0] = status;
    for (int i = 0; i < words; ++i) {
        m->response[1 + 2 * i] = (uint8_t)(out[i] >> 8);  // MSB first
        m->response[2 + 2 * i] = (uint8_t)out[i];
    }
    m->response_length = 1 + 2 * words;
    m->response_read = 0;
    m->command_length = 0;
}

// ------------------------------------------------------------------ the bus

static void reply(uint8_t msg, uint8_t addr, uint8_t data) {
    avr_raise_irq(sim.twi_input, avr_twi_irq_msg(msg, addr, data));
}

// The device answering a 7-bit address, or -2 for none.
static int device_at(uint8_t address) {
    if (address == MUX_ADDRESS) return -1;
    if (address != MLX_ADDRESS) return -2;
    int found = -2;
    for (int i = 0; i < sim.chips; ++i) {
        if (!(sim.mux_channels & (1 << i))) continue;
        if (found != -2) {
            fprintf(stderr, "fingertip_sim: two chips at 0x%02x on the bus (mux channels 0x%02x)\n", address,
                    sim.mux_channels);
            return -2;
        }
        found = i;
    }
    return found >= 0 && sim.mlx[found].naks ? -2 : found;
}

static void twi_message(avr_irq_t *irq, uint32_t value, void *param) {
    avr_twi_msg_irq_t msg;
    msg.u.v = value;
    (void)irq, (void)param;
    if (msg.u.twi.msg & TWI_COND_STOP) {
        if (sim.addressed >= 0 && !sim.reading && sim.mlx[sim.addressed].command_length)
            mlx_execute(&sim.mlx[sim.addressed]);  // a command written without reading its status
        sim.addressed = -2;
    }
    if (msg.u.twi.msg & TWI_COND_START) {
        const int device = device_at(msg.u.twi.addr >> 1);
        const int read = msg.u.twi.addr & 1;
        // A repeated start from writing a command to reading its answer executes the command.
        if (read && device >= 0 && device == sim.addressed && !sim.reading) mlx_execute(&sim.mlx[device]);
        if (!read && device >= 0) sim.mlx[device].command_length = 0;
        if (read && device >= 0 && device != sim.addressed) {
            sim.mlx[device].response_length = 0;
            sim.mlx[device].response_read = 0;
        }
        sim.addressed = device;
        sim.reading = read;
        if (device != -2) reply(TWI_COND_ACK, msg.u.twi.addr, 1);
        return;
    }
    if (sim.addressed == -2) return;
    if (msg.u.twi.msg & TWI_COND_WRITE) {
        if (sim.addressed == -1) {
            sim.mux_channels = msg.u.twi.data;
        } else {
            mlx_t *m = &sim.mlx[sim.addressed];
            if (m->command_length < (int)sizeof m->command) m->command[m->command_length++] = msg.u.twi.data;
        }
        reply(TWI_COND_ACK, msg.u.twi.addr, 1);
    }
    if (msg.u.twi.msg & TWI_COND_READ) {
        uint8_t data = 0xFF;
        if (sim.addressed == -1) {
            data = sim.mux_channels;
        } else {
            mlx_t *m = &sim.mlx[sim.addressed];
            if (m->response_read < m->response_length) data = m->response[m->response_read++];
        }
        reply(TWI_COND_READ, msg.u.twi.addr, data);
    }
}

static uint32_t bus_clock_cycles(avr_t *avr) {
    const uint32_t prescale = 1u << (2 * (avr->data[TWSR_ADDRESS] & 3));
    return 16u + 2u * avr->data[TWBR_ADDRESS] * prescale;
}

static avr_cycle_count_t stop_sent(avr_t *avr, avr_cycle_count_t when, void *param) {
    (void)when, (void)param;
    avr->data[TWCR_ADDRESS] &= (uint8_t)~(1 << TWSTO_BIT);
    return 0;
}

// simavr schedules each bus state as a number of 1 us bus clocks; stretch it to the clock the
// firmware configured (SCL = F_CPU / (16 + 2 * TWBR * 4^TWPS)). simavr 1.6 gives a START, a STOP
// and the address byte of a write no time: they take 1, 1 and 9 bus clocks here (TWSTO stays set
// until the STOP is sent, as the hardware keeps it). With SDA held low no START completes.
static void twcr_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
    (void)param;
    const uint8_t before = avr->data[TWCR_ADDRESS];
    const int starting = (v & (1 << TWSTA_BIT)) && !(before & (1 << TWSTA_BIT));
    const int stopping = (v & (1 << TWSTO_BIT)) && !(before & (1 << TWSTO_BIT)) && sim.twi->state;
    const int was_addressed = sim.twi->state & TWI_COND_ADDR;
    sim.twcr_write(avr, addr, v, sim.twi);
    if (stopping) {
        avr->data[TWCR_ADDRESS] |= 1 << TWSTO_BIT;
        avr_cycle_timer_register(avr, bus_clock_cycles(avr), stop_sent, NULL);
    }
    const int address_sent = !was_addressed && (sim.twi->state & TWI_COND_ADDR);
    for (avr_cycle_timer_slot_p slot = avr->cycle_timers.timer; slot; slot = slot->next) {
        if (slot->param != sim.twi) continue;
        const avr_cycle_timer_t timer = slot->timer;
        if (sim.stuck_bus && starting) {
            avr_cycle_timer_cancel(avr, timer, sim.twi);
            return;
        }
        const avr_cycle_count_t usec_cycles = slot->when > avr->cycle ? slot->when - avr->cycle : 0;
        const uint32_t bit_cycles = bus_clock_cycles(avr);
        avr_cycle_count_t bus_clocks = usec_cycles / avr_usec_to_cycles(avr, 1);
        if (address_sent) bus_clocks = 9;
        else if (starting) bus_clocks = 1;
        if (bus_clocks == 0) return;
        avr_cycle_timer_cancel(avr, timer, sim.twi);
        avr_cycle_timer_register(avr, bus_clocks * bit_cycles, timer, sim.twi);
        return;
    }
}

// ------------------------------------------------------------------ the serial port

// Bytes leave in the UART's order; a DATA frame's end is noted with the simulated time its last bit
// leaves the pin (simavr raises the output when the byte enters the shift register).
static void uart_output(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq, (void)param;
    const uint8_t byte = (uint8_t)value;
    if (sim.tx_length < sizeof sim.tx) sim.tx[sim.tx_length++] = byte;
    frame_scan_t *f = &sim.scan;
    if (f->got == 0 && byte != 0xA5) return;
    if (f->got == 1 && byte != 0x5A) {
        f->got = byte == 0xA5;
        return;
    }
    if (f->got < (int)sizeof f->head) f->head[f->got] = byte;
    ++f->got;
    if (f->got < 5 || f->got < 5 + f->head[4] + 2) return;
    if (f->head[3] == 0x01 && f->head[4] >= 8 && sim.frames_pending < MAX_PENDING_FRAMES) {
        const uint8_t ucsr0a = sim.avr->data[0xC0], ubrr = sim.avr->data[0xC4];
        const uint32_t cycles_per_bit = (ucsr0a & 0x02 ? 8u : 16u) * (ubrr + 1u);
        pending_frame_t *pending = &sim.frames[sim.frames_pending++];
        pending->seq = (uint16_t)(f->head[5] | f->head[6] << 8);
        pending->end_ns = sim_ns(sim.avr->cycle + 10u * cycles_per_bit);
    }
    f->got = 0;
}

static void uart_xon(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq, (void)value, (void)param;
    sim.uart_ready = 1;
}

static void uart_xoff(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq, (void)value, (void)param;
    sim.uart_ready = 0;
}

static void open_pty(const char *link) {
    int slave;
    char name[256];
    if (openpty(&sim.pty, &slave, name, NULL, NULL) != 0) die("cannot open a pseudo-terminal");
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    close(slave);  // the host opens it by name
    fcntl(sim.pty, F_SETFL, fcntl(sim.pty, F_GETFL) | O_NONBLOCK);
    if (link) {
        unlink(link);
        if (symlink(name, link) != 0) die("--link: cannot create the link");
    }
    printf("pty %s\n", name);
}

static void service_serial(avr_irq_t *uart_input) {
    size_t done = 0;
    while (done < sim.tx_length) {
        ssize_t n = write(sim.pty, sim.tx + done, sim.tx_length - done);
        if (n <= 0) break;  // nobody reads yet (or a full buffer): a real UART's bytes would be lost too
        done += (size_t)n;
    }
    sim.tx_length = 0;
    const int64_t written_ns = wall_ns();
    for (int i = 0; i < sim.frames_pending; ++i)
        printf("frame %u %lld %lld\n", sim.frames[i].seq, (long long)sim.frames[i].end_ns, (long long)written_ns);
    sim.frames_pending = 0;
    // One byte at a time while the UART's receive FIFO has room; it paces them at the baud rate.
    uint8_t byte;
    while (sim.uart_ready && read(sim.pty, &byte, 1) == 1) avr_raise_irq(uart_input, byte);
}

// ------------------------------------------------------------------ control

static void control(char *line) {
    int chip, on;
    if (sscanf(line, "nak %d %d", &chip, &on) == 2 && chip >= 0 && chip < sim.chips) {
        sim.mlx[chip].naks = on;
    } else if (sscanf(line, "stuck %d", &on) == 1) {
        sim.stuck_bus = on;
    } else if (sscanf(line, "reset %d", &chip) == 1 && chip >= 0 && chip < sim.chips) {
        mlx_power_on(&sim.mlx[chip]);
    } else if (sscanf(line, "burst %d", &chip) == 1 && chip >= 0 && chip < sim.chips) {
        sim.mlx[chip].mode = STATUS_BURST;  // as if something had started burst mode: SM is refused until EX
    } else if (strncmp(line, "time", 4) == 0) {
        printf("time %lld %lld\n", (long long)sim_ns(sim.avr->cycle), (long long)wall_ns());
    } else if (strncmp(line, "regs", 4) == 0) {
        for (int i = 0; i < sim.chips; ++i) printf("regs %d %04x %04x\n", i, sim.mlx[i].reg[0], sim.mlx[i].reg[2]);
    } else if (strncmp(line, "quit", 4) == 0) {
        printf("time %lld %lld\n", (long long)sim_ns(sim.avr->cycle), (long long)wall_ns());
        fflush(stdout);
        exit(0);
    } else if (line[0]) {
        fprintf(stderr, "fingertip_sim: unknown control line: %s\n", line);
    }
}

static void service_control(void) {
    static char buffer[256];
    static size_t length;
    ssize_t n = read(STDIN_FILENO, buffer + length, sizeof buffer - 1 - length);
    if (n == 0) control("quit");  // the controlling process went away
    if (n <= 0) return;
    length += (size_t)n;
    buffer[length] = 0;
    char *start = buffer, *newline;
    while ((newline = strchr(start, '\n'))) {
        *newline = 0;
        control(start);
        start = newline + 1;
    }
    length = strlen(start);
    memmove(buffer, start, length + 1);
    if (length == sizeof buffer - 1) length = 0;
}

// ------------------------------------------------------------------ main

int main(int argc, char **argv) {
    const char *elf = NULL, *fields = NULL, *link = NULL;
    sim.chips = 0;
    sim.temperature_c = 25.0;
    for (int i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--chips") && i + 1 < argc) sim.chips = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--fields") && i + 1 < argc) fields = argv[++i];
        else if (!strcmp(argv[i], "--link") && i + 1 < argc) link = argv[++i];
        else if (!strcmp(argv[i], "--temperature-c") && i + 1 < argc) sim.temperature_c = atof(argv[++i]);
        else if (argv[i][0] != '-' && !elf) elf = argv[i];
        else die("usage: fingertip_sim FIRMWARE.elf --chips N --fields PATH [--link PATH] [--temperature-c T]");
    }
    if (!elf) die("no firmware ELF given");
    if (sim.chips < 1 || sim.chips > MAX_CHIPS) die("--chips: expected 1 to 8");
    if (!fields) die("--fields: a file or pipe of field values is required");
    setvbuf(stdout, NULL, _IOLBF, 0);
    open_fields(&sim.fields, fields, sim.chips);

    elf_firmware_t firmware;
    memset(&firmware, 0, sizeof firmware);
    if (elf_read_firmware(elf, &firmware) != 0) die("cannot read the firmware ELF");
    sim.avr = avr_make_mcu_by_name("atmega328p");
    if (!sim.avr) die("simavr has no atmega328p");
    avr_init(sim.avr);
    sim.avr->frequency = 16000000;
    sim.avr->log = LOG_ERROR;
    avr_load_firmware(sim.avr, &firmware);

    for (int i = 0; i < sim.chips; ++i) {
        sim.mlx[i].index = i;
        mlx_power_on(&sim.mlx[i]);
    }
    sim.addressed = -2;
    static const char *names[] = {"32<fingertip.twi.in", "8>fingertip.twi.out"};
    avr_irq_t *bus = avr_alloc_irq(&sim.avr->irq_pool, 0, 2, names);
    avr_irq_register_notify(bus, twi_message, NULL);
    avr_connect_irq(avr_io_getirq(sim.avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), bus);
    sim.twi_input = avr_io_getirq(sim.avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT);
    const avr_io_addr_t twcr = AVR_DATA_TO_IO(TWCR_ADDRESS);
    sim.twi = sim.avr->io[twcr].w.param;
    sim.twcr_write = sim.avr->io[twcr].w.c;
    sim.avr->io[twcr].w.c = twcr_write;

    uint32_t flags = 0;
    avr_ioctl(sim.avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~AVR_UART_FLAG_STDIO;
    avr_ioctl(sim.avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(sim.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_output, NULL);
    avr_irq_register_notify(avr_io_getirq(sim.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), uart_xon, NULL);
    avr_irq_register_notify(avr_io_getirq(sim.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), uart_xoff, NULL);
    avr_irq_t *uart_input = avr_io_getirq(sim.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    sim.uart_ready = 1;
    open_pty(link);
    fcntl(STDIN_FILENO, F_SETFL, fcntl(STDIN_FILENO, F_GETFL) | O_NONBLOCK);

    const int64_t start_wall = wall_ns();
    avr_cycle_count_t next_poll = POLL_CYCLES, next_report = REPORT_CYCLES;
    for (;;) {
        const int state = avr_run(sim.avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            fprintf(stderr, "fingertip_sim: the firmware stopped (%s) at %.6f s\n",
                    state == cpu_Done ? "done" : "crashed", sim_ns(sim.avr->cycle) * 1e-9);
            return 1;
        }
        if (sim.avr->cycle < next_poll) continue;
        next_poll = sim.avr->cycle + POLL_CYCLES;
        service_serial(uart_input);
        service_control();
        read_fifo_rows(&sim.fields, sim.chips);
        const int64_t ahead = sim_ns(sim.avr->cycle) - (wall_ns() - start_wall);
        if (ahead > 0) {
            struct timespec pause = {ahead / 1000000000, ahead % 1000000000};
            nanosleep(&pause, NULL);
        }
        if (sim.avr->cycle >= next_report) {
            next_report += REPORT_CYCLES;
            printf("time %lld %lld\n", (long long)sim_ns(sim.avr->cycle), (long long)wall_ns());
        }
    }
}
