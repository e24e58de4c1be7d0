// act_drive --list-cameras / --list-ports: what can be given to --camera and --serial on this machine.
#pragma once

#include <ostream>

namespace act::drive {

/// V4L2 capture devices (/dev/videoN and the name the driver gives it), one a line; says so when none.
void list_cameras(std::ostream& out);
/// Serial ports through libserialport, USB ones with their maker, product and VID:PID (an Arduino
/// clone shows up as e.g. "1a86:7523 QinHeng CH340"); says so when none. Throws act::Error when the
/// ports cannot be listed.
void list_ports(std::ostream& out);

}  // namespace act::drive
