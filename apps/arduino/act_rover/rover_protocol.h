// The act_drive <-> Arduino serial protocol: one parser and formatter shared by the sketch
// (act_rover.ino) and the host (act_drive and its tests), so both ends agree by construction.
//
// It lives in the sketch folder because the Arduino tools only compile files next to the .ino;
// the host build compiles this same file. Plain C-compatible C++: no allocation, no exceptions,
// no floating point, fixed-size buffers, 16-bit fields (cheap on an 8-bit AVR).
//
// Line format (ASCII): '$' TYPE { ',' FIELD } '*' CRC '\n'
//   TYPE  one upper-case letter; FIELD  decimal 0..65535, 1 to 5 digits;
//   CRC   CRC-8 (polynomial 0x07, initial 0) of the bytes between '$' and '*', 2 upper-case hex digits.
//   A '\r' before the '\n' is ignored. A line is at most ROVER_MAX_LINE bytes with its newline.
// Host -> board:  C,seq,steer_us,throttle_us   drive (pulse widths in microseconds)
//                 F,seq,steer_us,throttle_us   set the failsafe outputs used after a timeout
//                 H                            hello: the board answers with its ready line
// Board -> host:  R,version,timeout_ms         ready (after boot and on H)
//                 A,seq                        a C or F line was accepted
//                 E,code                       a line was rejected (code: enum RoverError)
//                 N                            no valid command for timeout_ms: outputs at failsafe
#pragma once

#include <stddef.h>
#include <stdint.h>

#define ROVER_PROTOCOL_VERSION 1
#define ROVER_MAX_LINE 40       /* bytes, newline included */
#define ROVER_MAX_FIELDS 3
#define ROVER_PWM_MIN_US 800    /* pulse widths outside this range are rejected */
#define ROVER_PWM_MAX_US 2200
#define ROVER_PWM_NEUTRAL_US 1500
#define ROVER_WATCHDOG_MS 250   /* the board goes to failsafe after this long without a valid command */

enum RoverError {
  ROVER_OK = 0,
  ROVER_ERR_CHECKSUM = 1,      /* CRC does not match: a corrupted line */
  ROVER_ERR_MALFORMED = 2,     /* not '$' TYPE fields '*' CRC, or a field is not a number */
  ROVER_ERR_TOO_LONG = 3,      /* more than ROVER_MAX_LINE bytes before the newline */
  ROVER_ERR_RANGE = 4,         /* a pulse width outside ROVER_PWM_MIN_US..ROVER_PWM_MAX_US */
  ROVER_ERR_UNKNOWN_TYPE = 5,  /* a type letter this protocol does not have, or the wrong field count */
};

struct RoverMessage {
  char type;  /* 'C', 'F', 'H', 'R', 'A', 'E', 'N' */
  uint8_t field_count;
  uint16_t fields[ROVER_MAX_FIELDS];
};

/* Assembles lines from a byte stream. */
struct RoverLineReader {
  char text[ROVER_MAX_LINE + 1];
  uint8_t length;
  uint8_t overflow;   /* the current line exceeded ROVER_MAX_LINE; it must be rejected as too long */
  uint8_t line_done;  /* the last push completed a line */
};

void rover_reader_init(struct RoverLineReader* reader);
/* Feeds one byte. Returns 1 when a line is complete: reader->text holds it NUL-terminated, without
   the newline, reader->length its length (a line that overflowed has reader->overflow set and must
   be rejected as ROVER_ERR_TOO_LONG). Returns 0 otherwise. The next push starts a new line. */
int rover_reader_push(struct RoverLineReader* reader, char byte);

uint8_t rover_crc8(const char* data, size_t length);

/* Number of fields a message type carries, or -1 for a type the protocol does not have. */
int rover_field_count(char type);

/* Parses one line (without its newline; a trailing '\r' is allowed). Returns ROVER_OK and fills
   *out, or the RoverError that explains the rejection. */
enum RoverError rover_parse(const char* line, size_t length, struct RoverMessage* out);

/* Writes the message as a line, newline included, NUL-terminated. Returns its length without the
   NUL, or 0 when the capacity is too small or the message does not fit the protocol. */
size_t rover_format(const struct RoverMessage* message, char* out, size_t capacity);

/* True when more than ROVER_WATCHDOG_MS have passed since last_valid_ms (a millisecond clock that
   wraps around, like Arduino's millis()). */
int rover_watchdog_expired(uint32_t last_valid_ms, uint32_t now_ms);
