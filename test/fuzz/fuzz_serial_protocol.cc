// libFuzzer target: the act_drive <-> Arduino serial protocol (apps/arduino/act_rover/rover_protocol),
// the code both the board and the host run on every byte from the wire. The input is a byte stream
// fed through the line reader; every complete line is parsed, and a line that parses must format
// back to a line that parses to the same message (both ends agree by construction).
#include <cstdlib>
#include <cstring>

#include "apps/arduino/act_rover/rover_protocol.h"

namespace {

void check_round_trip(const RoverMessage& message) {
  char line[ROVER_MAX_LINE + 1];
  const size_t length = rover_format(&message, line, sizeof line);
  if (length == 0) return;  // a message the formatter refuses (e.g. a field count it has no room for)
  if (length > ROVER_MAX_LINE || line[length - 1] != '\n' || line[length] != '\0') std::abort();
  RoverMessage again{};
  if (rover_parse(line, length - 1, &again) != ROVER_OK) std::abort();
  if (again.type != message.type || again.field_count != message.field_count ||
      std::memcmp(again.fields, message.fields, message.field_count * sizeof(uint16_t)) != 0) {
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  RoverLineReader reader;
  rover_reader_init(&reader);
  for (size_t i = 0; i < size; ++i) {
    if (!rover_reader_push(&reader, static_cast<char>(data[i]))) continue;
    if (reader.length > ROVER_MAX_LINE || reader.text[reader.length] != '\0') std::abort();
    if (reader.overflow) continue;  // rejected as too long by the caller
    RoverMessage message{};
    if (rover_parse(reader.text, reader.length, &message) == ROVER_OK) check_round_trip(message);
  }
  // The whole input as one line, as a caller with its own framing would pass it.
  RoverMessage message{};
  if (rover_parse(reinterpret_cast<const char*>(data), size, &message) == ROVER_OK) check_round_trip(message);
  return 0;
}
