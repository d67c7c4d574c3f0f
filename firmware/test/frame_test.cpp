// Host-side test driver for the firmware's protocol unit (softtip_fingertip/protocol.cpp).
//
// Reads one request per line on stdin and answers with one or more lines on stdout,
// so that a test on the host can compare the firmware's encoder byte for byte with
// another implementation. Numbers are decimal; byte strings are hexadecimal.
//
//   crc <hex>                            -> crc <value>
//   data <seq> <time_us> <flags> <n> {<status> <x> <y> <z> [<t>]}*n   -> frame <hex>
//   identity <tag> <chips> <name-hex>    -> frame <hex>
//   ack <command> <tag>                  -> frame <hex>
//   error <command> <tag> <code> <detail> -> frame <hex>
//   command <type> <payload-hex>         -> frame <hex>
//   parse <hex>                          -> command <type> <tag> <args-hex> (per command),
//                                           then parsed <crc_errors> <bytes_discarded>
//   settings <args-hex>                  -> settings <error code> <conversion time us>
//   rate <args-hex>                      -> rate <error code> <rate hz>
//
// Build: g++ -std=c++11 -I../softtip_fingertip frame_test.cpp ../softtip_fingertip/protocol.cpp
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "protocol.h"

namespace {

std::vector<uint8_t> from_hex(const std::string &text) {
    std::vector<uint8_t> bytes;
    for (size_t i = 0; i + 1 < text.size(); i += 2) {
        bytes.push_back(static_cast<uint8_t>(std::strtoul(text.substr(i, 2).c_str(), 0, 16)));
    }
    return bytes;
}

std::string to_hex(const uint8_t *data, size_t length) {
    static const char digits[] = "0123456789abcdef";
    std::string text;
    for (size_t i = 0; i < length; ++i) {
        text += digits[data[i] >> 4];
        text += digits[data[i] & 0x0F];
    }
    return text;
}

unsigned long number(std::istringstream &words) {
    std::string word;
    words >> word;
    return std::strtoul(word.c_str(), 0, 10);
}

void print_frame(const uint8_t *frame, size_t length) {
    std::cout << "frame " << to_hex(frame, length) << "\n";
}

bool answer(const std::string &line) {
    std::istringstream words(line);
    std::string request;
    words >> request;
    uint8_t frame[softtip::MAX_DATA_FRAME];
    if (request == "crc") {
        std::string hex;
        words >> hex;
        const std::vector<uint8_t> bytes = from_hex(hex);
        std::cout << "crc " << softtip::crc16(bytes.data(), bytes.size()) << "\n";
    } else if (request == "data") {
        const uint16_t seq = static_cast<uint16_t>(number(words));
        const uint32_t time_us = static_cast<uint32_t>(number(words));
        const uint8_t flags = static_cast<uint8_t>(number(words));
        const uint8_t count = static_cast<uint8_t>(number(words));
        if (count < 1 || count > softtip::MAX_CHIPS) return false;
        softtip::ChipReading chips[softtip::MAX_CHIPS];
        for (uint8_t i = 0; i < count; ++i) {
            chips[i].status = static_cast<uint8_t>(number(words));
            chips[i].x = static_cast<uint16_t>(number(words));
            chips[i].y = static_cast<uint16_t>(number(words));
            chips[i].z = static_cast<uint16_t>(number(words));
            chips[i].temperature =
                (flags & softtip::DATA_TEMPERATURE) ? static_cast<uint16_t>(number(words)) : 0;
        }
        print_frame(frame, softtip::encode_data(frame, seq, time_us, flags, chips, count));
    } else if (request == "identity") {
        const uint8_t tag = static_cast<uint8_t>(number(words));
        const uint8_t chips = static_cast<uint8_t>(number(words));
        std::string hex;
        words >> hex;
        std::vector<uint8_t> name = from_hex(hex);
        std::string text(name.begin(), name.end());
        print_frame(frame, softtip::encode_identity(frame, tag, chips, text.c_str()));
    } else if (request == "ack") {
        const uint8_t command = static_cast<uint8_t>(number(words));
        const uint8_t tag = static_cast<uint8_t>(number(words));
        print_frame(frame, softtip::encode_ack(frame, command, tag));
    } else if (request == "error") {
        const uint8_t command = static_cast<uint8_t>(number(words));
        const uint8_t tag = static_cast<uint8_t>(number(words));
        const uint8_t code = static_cast<uint8_t>(number(words));
        const uint8_t detail = static_cast<uint8_t>(number(words));
        print_frame(frame, softtip::encode_error(frame, command, tag, code, detail));
    } else if (request == "command") {
        const uint8_t type = static_cast<uint8_t>(number(words));
        std::string hex;
        words >> hex;
        const std::vector<uint8_t> payload = from_hex(hex);
        if (payload.size() > softtip::MAX_COMMAND_PAYLOAD) return false;
        print_frame(frame, softtip::encode_frame(frame, type, payload.data(),
                                                 static_cast<uint8_t>(payload.size())));
    } else if (request == "parse") {
        std::string hex;
        words >> hex;
        softtip::CommandParser parser;
        const std::vector<uint8_t> stream = from_hex(hex);
        for (size_t i = 0; i < stream.size(); ++i) {
            parser.feed(stream[i]);
            while (parser.next()) {
                std::cout << "command " << static_cast<unsigned>(parser.type()) << " "
                          << static_cast<unsigned>(parser.tag()) << " "
                          << to_hex(parser.args(), parser.args_length()) << "\n";
            }
        }
        std::cout << "parsed " << parser.crc_errors() << " " << parser.bytes_discarded() << "\n";
    } else if (request == "settings") {
        std::string hex;
        words >> hex;
        const std::vector<uint8_t> args = from_hex(hex);
        softtip::SensorSettings settings = softtip::default_settings();
        const uint8_t code = softtip::decode_settings(args.data(),
                                                      static_cast<uint8_t>(args.size()), &settings);
        std::cout << "settings " << static_cast<unsigned>(code) << " "
                  << (code ? 0 : softtip::conversion_time_us(settings)) << "\n";
    } else if (request == "rate") {
        std::string hex;
        words >> hex;
        const std::vector<uint8_t> args = from_hex(hex);
        uint16_t rate = 0;
        const uint8_t code =
            softtip::decode_rate(args.data(), static_cast<uint8_t>(args.size()), &rate);
        std::cout << "rate " << static_cast<unsigned>(code) << " " << rate << "\n";
    } else {
        return false;
    }
    return true;
}

}  // namespace

int main() {
    std::string line;
    while (std::getline(std::cin, line)) {
        if (line.empty()) continue;
        if (!answer(line)) {
            std::cerr << "frame_test: cannot answer: " << line << "\n";
            return 2;
        }
    }
    return 0;
}
