// The shared serial protocol (see rover_protocol.h). Compiled into the Arduino sketch and the host.
#include "rover_protocol.h"

void rover_reader_init(struct RoverLineReader* reader) {
  reader->length = 0;
  reader->overflow = 0;
  reader->line_done = 0;
  reader->text[0] = '\0';
}

int rover_reader_push(struct RoverLineReader* reader, char byte) {
  if (reader->line_done) {  // the previous push returned a line: this byte starts the next one
    reader->length = 0;
    reader->overflow = 0;
    reader->line_done = 0;
  }
  if (byte == '\n') {
    reader->text[reader->length] = '\0';
    reader->line_done = 1;
    return 1;
  }
  if (reader->length + 1 >= ROVER_MAX_LINE) {  // the newline counts in ROVER_MAX_LINE
    // Drop the rest of an overlong line, up to its newline.
    reader->overflow = 1;
    return 0;
  }
  reader->text[reader->length++] = byte;
  return 0;
}

uint8_t rover_crc8(const char* data, size_t length) {
  uint8_t crc = 0;
  for (size_t i = 0; i < length; ++i) {
    crc = static_cast<uint8_t>(crc ^ static_cast<uint8_t>(data[i]));
    for (int bit = 0; bit < 8; ++bit) {
      crc = (crc & 0x80) ? static_cast<uint8_t>((crc << 1) ^ 0x07) : static_cast<uint8_t>(crc << 1);
    }
  }
  return crc;
}

int rover_field_count(char type) {
  switch (type) {
    case 'C': case 'F': return 3;
    case 'R': return 2;
    case 'A': case 'E': return 1;
    case 'H': case 'N': return 0;
    default: return -1;
  }
}

static int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

static int carries_pulse_widths(char type) { return type == 'C' || type == 'F'; }

enum RoverError rover_parse(const char* line, size_t length, struct RoverMessage* out) {
  if (length > 0 && line[length - 1] == '\r') --length;
  if (length + 1 > ROVER_MAX_LINE) return ROVER_ERR_TOO_LONG;
  // Shortest line: "$H*00".
  if (length < 5 || line[0] != '$' || line[length - 3] != '*') return ROVER_ERR_MALFORMED;
  const int hi = hex_value(line[length - 2]);
  const int lo = hex_value(line[length - 1]);
  if (hi < 0 || lo < 0) return ROVER_ERR_MALFORMED;
  const size_t body_end = length - 3;  // index of '*'
  if (rover_crc8(line + 1, body_end - 1) != static_cast<uint8_t>(hi * 16 + lo)) return ROVER_ERR_CHECKSUM;

  struct RoverMessage message;
  message.type = line[1];
  message.field_count = 0;
  for (int i = 0; i < ROVER_MAX_FIELDS; ++i) message.fields[i] = 0;
  const int expected = rover_field_count(message.type);
  if (expected < 0) return ROVER_ERR_UNKNOWN_TYPE;

  size_t pos = 2;
  while (pos < body_end) {
    if (line[pos] != ',' || message.field_count >= ROVER_MAX_FIELDS) return ROVER_ERR_MALFORMED;
    ++pos;
    uint32_t value = 0;
    size_t digits = 0;
    while (pos < body_end && line[pos] >= '0' && line[pos] <= '9') {
      value = value * 10 + static_cast<uint32_t>(line[pos] - '0');
      ++pos;
      if (++digits > 5) return ROVER_ERR_MALFORMED;
    }
    if (digits == 0 || value > 65535) return ROVER_ERR_MALFORMED;
    message.fields[message.field_count++] = static_cast<uint16_t>(value);
  }
  if (message.field_count != expected) return ROVER_ERR_UNKNOWN_TYPE;
  if (carries_pulse_widths(message.type)) {
    for (int i = 1; i < 3; ++i) {
      if (message.fields[i] < ROVER_PWM_MIN_US || message.fields[i] > ROVER_PWM_MAX_US) return ROVER_ERR_RANGE;
    }
  }
  *out = message;
  return ROVER_OK;
}

// Appends the decimal digits of value at out[pos]; returns the new position.
static size_t put_decimal(char* out, size_t pos, uint16_t value) {
  char digits[5];
  size_t n = 0;
  do {
    digits[n++] = static_cast<char>('0' + value % 10);
    value = static_cast<uint16_t>(value / 10);
  } while (value != 0);
  while (n > 0) out[pos++] = digits[--n];
  return pos;
}

size_t rover_format(const struct RoverMessage* message, char* out, size_t capacity) {
  static const char kHex[] = "0123456789ABCDEF";
  if (rover_field_count(message->type) != message->field_count) return 0;
  // Build into a local buffer of the protocol's maximum size, then copy if it fits.
  char line[ROVER_MAX_LINE + 8];
  size_t pos = 0;
  line[pos++] = '$';
  line[pos++] = message->type;
  for (uint8_t i = 0; i < message->field_count; ++i) {
    line[pos++] = ',';
    pos = put_decimal(line, pos, message->fields[i]);
  }
  const uint8_t crc = rover_crc8(line + 1, pos - 1);
  line[pos++] = '*';
  line[pos++] = kHex[crc >> 4];
  line[pos++] = kHex[crc & 0x0F];
  line[pos++] = '\n';
  if (pos > ROVER_MAX_LINE || pos + 1 > capacity) return 0;
  for (size_t i = 0; i < pos; ++i) out[i] = line[i];
  out[pos] = '\0';
  return pos;
}

int rover_watchdog_expired(uint32_t last_valid_ms, uint32_t now_ms) {
  return static_cast<uint32_t>(now_ms - last_valid_ms) > ROVER_WATCHDOG_MS;
}
