// Just enough of the Arduino API to compile apps/arduino/act_rover/act_rover.ino on the host, so
// the sketch's own logic (acks, rejections, watchdog) is tested, not only its protocol unit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <string>

#ifndef F_CPU
#define F_CPU 16000000UL
#endif
#define OUTPUT 1
#define _BV(bit) (1 << (bit))

// Timer1 registers and bits (ATmega328P numbering).
inline volatile uint8_t TCCR1A = 0, TCCR1B = 0;
inline volatile uint16_t ICR1 = 0, OCR1A = 0, OCR1B = 0;
enum { WGM11 = 1, COM1B1 = 5, COM1A1 = 7, CS11 = 1, WGM12 = 3, WGM13 = 4 };

namespace arduino_stub {
inline uint32_t now_ms = 0;
inline uint8_t pin_modes[64] = {};
}  // namespace arduino_stub

inline uint32_t millis() { return arduino_stub::now_ms; }
inline void pinMode(uint8_t pin, uint8_t mode) { arduino_stub::pin_modes[pin] = mode; }

class StubSerial {
 public:
  void begin(long baud) { baud_ = baud; }
  int available() const { return static_cast<int>(input_.size()); }
  int read() {
    if (input_.empty()) return -1;
    const char c = input_.front();
    input_.pop_front();
    return static_cast<unsigned char>(c);
  }
  size_t write(const uint8_t* data, size_t size) {
    output_.append(reinterpret_cast<const char*>(data), size);
    return size;
  }
  // Test side.
  void feed(const std::string& bytes) { input_.insert(input_.end(), bytes.begin(), bytes.end()); }
  std::string take_output() {
    std::string out;
    out.swap(output_);
    return out;
  }
  long baud() const { return baud_; }

 private:
  std::deque<char> input_;
  std::string output_;
  long baud_ = 0;
};
inline StubSerial Serial;
