"""What the operator needs to hear when a CAN adapter cannot be opened the way it was named.

The facility's adapter is an IXXAT USB-to-CAN. python-can's ``ixxat`` interface speaks
IXXAT's VCI driver, which exists for Windows only: on Linux the adapter is a SocketCAN
device (the kernel's ``ixx_usb`` / ``ixxat_usb2can`` driver), brought up with ``ip link``
and opened with ``-i socketcan -c can0``. Pure: the platform is passed in.
"""

from __future__ import annotations

#: The commands that bring the IXXAT USB-to-CAN up as SocketCAN (1 Mbit/s, the LWA 3's).
SOCKETCAN_BRING_UP = ("sudo ip link set can0 type can bitrate 1000000 && "
                      "sudo ip link set can0 up")


def adapter_hint(interface: str | None, platform: str) -> str | None:
    """One line saying how to reach this adapter on this platform instead, or None."""
    if interface == "ixxat" and platform.startswith("linux"):
        return ("-i ixxat needs IXXAT's VCI driver, which exists for Windows only; on Linux "
                "the IXXAT USB-to-CAN is a SocketCAN device: bring it up with "
                f"'{SOCKETCAN_BRING_UP}', then use -i socketcan -c can0 (README, "
                "docs/safety.md)")
    return None
