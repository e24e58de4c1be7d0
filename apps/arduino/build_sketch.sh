#!/usr/bin/env bash
# Builds the act_rover sketch with Debian's avr-gcc and Arduino AVR core (gcc-avr, avr-libc,
# arduino-core-avr), without the Arduino IDE: OUT_DIR/act_rover.hex, ready for avrdude.
#   apps/arduino/build_sketch.sh OUT_DIR [MCU] [F_CPU] [VARIANT]
# Defaults: atmega328p 16000000 standard (Uno, Nano). Leonardo: atmega32u4 16000000 leonardo;
# Mega: atmega2560 16000000 mega. Sketch and protocol unit build with -Wall -Wextra -Werror.
set -euo pipefail
out="${1:?usage: build_sketch.sh OUT_DIR [MCU] [F_CPU] [VARIANT]}"
mcu="${2:-atmega328p}"
f_cpu="${3:-16000000}"
variant="${4:-standard}"
here="$(cd "$(dirname "$0")" && pwd)"
sketch="$here/act_rover"
core="${ARDUINO_AVR_DIR:-/usr/share/arduino/hardware/arduino/avr}"

# A missing toolchain: exit 77 (ctest's "skipped"), except under CI=true where it is a failure.
missing() {
  echo "build_sketch: $1" >&2
  if [ "${CI:-}" = true ]; then exit 1; else exit 77; fi
}
for tool in avr-gcc avr-g++ avr-objcopy avr-size; do
  command -v "$tool" >/dev/null || missing "$tool not found (apt-get install gcc-avr avr-libc)"
done
[ -f "$core/cores/arduino/Arduino.h" ] || missing "no Arduino AVR core at $core (apt-get install arduino-core-avr)"

mkdir -p "$out/core"
common=(-mmcu="$mcu" -DF_CPU="${f_cpu}L" -DARDUINO=10807 -DARDUINO_ARCH_AVR -Os -ffunction-sections -fdata-sections
        -I"$core/cores/arduino" -I"$core/variants/$variant")
cxx=(-std=gnu++11 -fno-exceptions -fno-threadsafe-statics)
# USB boards: the identity the Arduino IDE's boards.txt gives a Leonardo.
if [ "$mcu" = atmega32u4 ]; then
  common+=(-DUSB_VID=0x2341 -DUSB_PID=0x8036 '-DUSB_MANUFACTURER="Unknown"' '-DUSB_PRODUCT="Arduino Leonardo"')
fi

objs=()
for src in "$core"/cores/arduino/*.c "$core"/cores/arduino/*.cpp "$core"/cores/arduino/*.S; do
  [ -f "$src" ] || continue
  obj="$out/core/$(basename "$src").o"
  case "$src" in
    *.c) avr-gcc "${common[@]}" -std=gnu11 -c "$src" -o "$obj" ;;
    # gcc-avr 5.4's <float.h> defines DECIMAL_DIG for C99 only; the core's WString.cpp needs it in C++.
    *.cpp) avr-g++ "${common[@]}" "${cxx[@]}" -DDECIMAL_DIG=__DECIMAL_DIG__ -c "$src" -o "$obj" ;;
    *.S) avr-gcc "${common[@]}" -x assembler-with-cpp -c "$src" -o "$obj" ;;
  esac
  objs+=("$obj")
done
avr-gcc-ar rcs "$out/core.a" "${objs[@]}" 2>/dev/null || avr-ar rcs "$out/core.a" "${objs[@]}"

strict=(-Wall -Wextra -Werror)
avr-g++ "${common[@]}" "${cxx[@]}" "${strict[@]}" -c "$sketch/rover_protocol.cpp" -o "$out/rover_protocol.o"
avr-g++ "${common[@]}" "${cxx[@]}" "${strict[@]}" -x c++ -c "$sketch/act_rover.ino" -o "$out/act_rover.o"
avr-gcc -mmcu="$mcu" -Os -Wl,--gc-sections "$out/act_rover.o" "$out/rover_protocol.o" "$out/core.a" -lm -o "$out/act_rover.elf"
avr-objcopy -O ihex -R .eeprom "$out/act_rover.elf" "$out/act_rover.hex"
avr-size "$out/act_rover.elf"
echo "build_sketch: $out/act_rover.hex ($mcu at $f_cpu Hz)"
