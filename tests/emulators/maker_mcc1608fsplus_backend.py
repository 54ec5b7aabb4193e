"""The pyusb side of the USB-1608FS-Plus emulator: a ``usb.backend.IBackend`` holding one emulated unit
(``maker_mcc1608fsplus.Usb1608FsPlus``), so ``usb.core.find(idVendor=0x09DB, idProduct=0x00EA, backend=...)``
finds it (facts: tests/emulators/MAKER_FACTS.md)."""

from __future__ import annotations

import errno
import struct
from types import SimpleNamespace

import usb.backend
import usb.core

from tests.emulators.maker_mcc1608fsplus import (
    BULK_IN_EP,
    MAX_PACKET,
    PRODUCT_ID,
    RESET,
    VENDOR_ID,
    Usb1608FsPlus,
    _pipe_error,
)


# -- the pyusb backend --------------------------------------------------------------------------------------------
def _device_descriptor() -> SimpleNamespace:
    return SimpleNamespace(
        bLength=18, bDescriptorType=1, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0,
        bMaxPacketSize0=64, idVendor=VENDOR_ID, idProduct=PRODUCT_ID, bcdDevice=0x0100, iManufacturer=1,
        iProduct=2, iSerialNumber=3, bNumConfigurations=1, address=2, bus=1, port_number=1, port_numbers=(1,),
        speed=2)  # full speed


_STRINGS = {1: "MCC", 2: "USB-1608FS-Plus"}


class Usb1608FsPlusBackend(usb.backend.IBackend):
    """A pyusb backend holding one emulated USB-1608FS-Plus (``device``)."""

    def __init__(self, device: Usb1608FsPlus) -> None:
        self.device = device
        self.configuration = 0
        self.claimed: set[int] = set()

    def enumerate_devices(self):
        yield self.device

    def get_device_descriptor(self, dev):
        return _device_descriptor()

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(config)
        return SimpleNamespace(bLength=9, bDescriptorType=2, wTotalLength=9 + 9 + 7, bNumInterfaces=1,
                               bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50,
                               extra_descriptors=[])

    def get_interface_descriptor(self, dev, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError((intf, alt, config))
        return SimpleNamespace(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0,
                               bNumEndpoints=1, bInterfaceClass=0xFF, bInterfaceSubClass=0, bInterfaceProtocol=0,
                               iInterface=0, extra_descriptors=[])

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if (ep, intf, alt, config) != (0, 0, 0, 0):
            raise IndexError((ep, intf, alt, config))
        return SimpleNamespace(bLength=7, bDescriptorType=5, bEndpointAddress=BULK_IN_EP, bmAttributes=0x02,
                               wMaxPacketSize=MAX_PACKET, bInterval=0, bRefresh=0, bSynchAddress=0,
                               extra_descriptors=[])

    def open_device(self, dev):
        return dev

    def close_device(self, dev_handle):
        self.claimed.clear()

    def set_configuration(self, dev_handle, config_value):
        if config_value not in (0, 1):
            raise _pipe_error()
        self.configuration = config_value

    def get_configuration(self, dev_handle):
        return self.configuration

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        if (intf, altsetting) != (0, 0):
            raise _pipe_error()

    def claim_interface(self, dev_handle, intf):
        self.claimed.add(intf)

    def release_interface(self, dev_handle, intf):
        self.claimed.discard(intf)

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def detach_kernel_driver(self, dev_handle, intf):
        pass

    def attach_kernel_driver(self, dev_handle, intf):
        pass

    def reset_device(self, dev_handle):
        self.device.control_out(RESET, 0, 0, b"")

    def clear_halt(self, dev_handle, ep):
        if ep == BULK_IN_EP:
            self.device.halted = False

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        if ep != BULK_IN_EP:
            raise _pipe_error()
        data = self.device.bulk_in(len(buff) * buff.itemsize)
        raw = memoryview(buff).cast("B")
        raw[: len(data)] = data
        return len(data)

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        raise _pipe_error()  # the unit has no bulk OUT endpoint

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        length = len(data) * data.itemsize
        self.device.requests.append((bmRequestType, bRequest, wValue, wIndex, length))
        kind = bmRequestType >> 5 & 0x3
        device_to_host = bool(bmRequestType & 0x80)
        if kind == 0:  # standard requests
            if device_to_host and bRequest == 6:
                reply = self._descriptor(wValue >> 8, wValue & 0xFF)[:length]
            elif bRequest in (1, 3, 9):  # CLEAR_FEATURE, SET_FEATURE, SET_CONFIGURATION
                return 0
            else:
                raise _pipe_error()
        elif kind == 2 and bmRequestType & 0x1F == 0:  # vendor, device recipient
            if not device_to_host:
                self.device.control_out(bRequest, wValue, wIndex, bytes(memoryview(data).cast("B")))
                return length
            reply = self.device.control_in(bRequest, wValue, wIndex, length)
            if len(reply) > length:
                raise usb.core.USBError("Overflow", -8, errno.EOVERFLOW)
        else:
            raise _pipe_error()
        memoryview(data).cast("B")[: len(reply)] = reply
        return len(reply)

    def _descriptor(self, kind: int, index: int) -> bytes:
        if kind == 3:  # string
            if index == 0:
                return bytes([4, 3, 0x09, 0x04])
            text = self.device.serial.decode() if index == 3 else _STRINGS.get(index)
            if text is None:
                raise _pipe_error()
            encoded = text.encode("utf-16-le")
            return bytes([2 + len(encoded), 3]) + encoded
        if kind == 1:
            d = _device_descriptor()
            return struct.pack("<BBHBBBBHHHBBBB", 18, 1, d.bcdUSB, 0, 0, 0, 64, VENDOR_ID, PRODUCT_ID,
                               d.bcdDevice, 1, 2, 3, 1)
        raise _pipe_error()
