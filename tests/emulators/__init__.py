"""Instrument emulators at the real boundary: serial instruments on pseudo-terminals, the MCC DAQ behind a
custom pyusb backend, NI-DAQmx as fake task objects. Tests drive the real drivers against them."""
