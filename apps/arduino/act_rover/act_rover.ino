// act_rover: the Arduino end of act_drive. Turns protocol lines from the host (rover_protocol.h)
// into servo and ESC pulses, acknowledges every line, and drops to its failsafe outputs by itself
// when no valid drive command arrives for ROVER_WATCHDOG_MS. The AVR's hardware watchdog resets a
// sketch that hangs (loop() stops running) within 120 ms: the reset stops the pulses and setup()
// starts again from neutral.
//
// Boards: ATmega328P (Uno, Nano, Pro Mini) and ATmega32U4 (Leonardo, Micro): steering on pin 9,
// ESC on pin 10; ATmega2560 (Mega): pins 11 and 12. The pulses come from Timer1's hardware PWM
// (50 Hz, 0.5 us resolution at 16 MHz), so serial traffic never makes them jitter.
#include <Arduino.h>
#include <avr/wdt.h>

#include "rover_protocol.h"

#ifndef ROVER_BAUD
#define ROVER_BAUD 115200
#endif

#if defined(__AVR_ATmega2560__) || defined(__AVR_ATmega1280__)
static const uint8_t kSteeringPin = 11;  // OC1A
static const uint8_t kThrottlePin = 12;  // OC1B
#else
static const uint8_t kSteeringPin = 9;   // OC1A
static const uint8_t kThrottlePin = 10;  // OC1B
#endif

#if defined(__AVR__)
// A watchdog reset leaves the watchdog running at its shortest timeout, which would reset the board
// again before setup() (bootloaders without this fix loop forever): switch it off first thing, before
// main() (.init3 runs right after the stack is set up).
extern "C" void disable_watchdog_at_boot() __attribute__((naked, used, section(".init3")));
extern "C" void disable_watchdog_at_boot() {
  MCUSR = 0;
  wdt_disable();
}
#endif

static const uint32_t kTimerTicksPerUs = F_CPU / 8000000UL;  // Timer1 runs at F_CPU / 8
static const uint16_t kFramePeriodUs = 20000;                // 50 Hz servo frame

static RoverLineReader reader;
static uint16_t failsafe_steering_us = ROVER_PWM_NEUTRAL_US;
static uint16_t failsafe_throttle_us = ROVER_PWM_NEUTRAL_US;
static uint32_t last_valid_ms = 0;
static bool in_failsafe = true;

static void write_pulses(uint16_t steering_us, uint16_t throttle_us) {
  OCR1A = static_cast<uint16_t>(steering_us * kTimerTicksPerUs);
  OCR1B = static_cast<uint16_t>(throttle_us * kTimerTicksPerUs);
}

static void send(const RoverMessage& message) {
  char line[ROVER_MAX_LINE + 1];
  const size_t length = rover_format(&message, line, sizeof line);
  Serial.write(reinterpret_cast<const uint8_t*>(line), length);
}

static void send_fields(char type, uint8_t count, uint16_t a, uint16_t b) {
  RoverMessage message;
  message.type = type;
  message.field_count = count;
  message.fields[0] = a;
  message.fields[1] = b;
  message.fields[2] = 0;
  send(message);
}

static void go_failsafe() {
  write_pulses(failsafe_steering_us, failsafe_throttle_us);
  in_failsafe = true;
}

static void handle_line() {
  if (reader.overflow) {
    send_fields('E', 1, ROVER_ERR_TOO_LONG, 0);
    return;
  }
  if (reader.length == 0 || (reader.length == 1 && reader.text[0] == '\r')) return;  // blank line
  RoverMessage message;
  const RoverError error = rover_parse(reader.text, reader.length, &message);
  if (error != ROVER_OK) {
    send_fields('E', 1, error, 0);
    return;
  }
  switch (message.type) {
    case 'C':
      write_pulses(message.fields[1], message.fields[2]);
      last_valid_ms = millis();
      in_failsafe = false;
      send_fields('A', 1, message.fields[0], 0);
      break;
    case 'F':
      failsafe_steering_us = message.fields[1];
      failsafe_throttle_us = message.fields[2];
      if (in_failsafe) go_failsafe();
      send_fields('A', 1, message.fields[0], 0);
      break;
    case 'H':
      send_fields('R', 2, ROVER_PROTOCOL_VERSION, ROVER_WATCHDOG_MS);
      break;
    default:  // a board-to-host message type: not something the host should send
      send_fields('E', 1, ROVER_ERR_UNKNOWN_TYPE, 0);
      break;
  }
}

void setup() {
  failsafe_steering_us = ROVER_PWM_NEUTRAL_US;
  failsafe_throttle_us = ROVER_PWM_NEUTRAL_US;
  in_failsafe = true;
  // Neutral before the outputs are enabled: an ESC must see neutral at power-up to arm safely.
  TCCR1A = 0;
  TCCR1B = 0;
  ICR1 = static_cast<uint16_t>(kFramePeriodUs * kTimerTicksPerUs - 1);
  write_pulses(failsafe_steering_us, failsafe_throttle_us);
  // Fast PWM with ICR1 as TOP (mode 14), non-inverting on OC1A and OC1B, prescaler 8.
  TCCR1A = _BV(COM1A1) | _BV(COM1B1) | _BV(WGM11);
  TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS11);
  pinMode(kSteeringPin, OUTPUT);
  pinMode(kThrottlePin, OUTPUT);

  rover_reader_init(&reader);
  Serial.begin(ROVER_BAUD);
  send_fields('R', 2, ROVER_PROTOCOL_VERSION, ROVER_WATCHDOG_MS);
  last_valid_ms = millis();
  wdt_enable(WDTO_120MS);  // well inside the protocol's 250 ms, far above one loop() pass
}

void loop() {
  wdt_reset();
  while (Serial.available() > 0) {
    if (rover_reader_push(&reader, static_cast<char>(Serial.read()))) handle_line();
  }
  if (!in_failsafe && rover_watchdog_expired(last_valid_ms, millis())) {
    go_failsafe();
    send_fields('N', 0, 0, 0);
  }
}
