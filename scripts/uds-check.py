#!/usr/bin/env python3
"""An independent UDS client against the running virtual car: udsoncan over can-isotp over
python-can's socketcand interface. It reads the identification DIDs (F187 part number,
F189 software version, F18C serial number, F191 hardware version) of all nine ECUs, then
runs a complete download of a signed image to one ECU (programming session, security
access, erase, RequestDownload, TransferData, RequestTransferExit, check, reset) and
reads the new software version back.

    scripts/uds-check.py HOST PORT IMAGE NODE EXPECTED_VERSION

Exit status 0 when everything answered as the standard says; the failing step otherwise.
The security secret is the development one of the project (autoplug_uds::DEV_SECURITY_SECRET):
a tester has to be configured with the secret its ECUs use.
"""

import hashlib
import hmac
import sys
import time

import can
import isotp
import udsoncan
from udsoncan.client import Client
from udsoncan.connections import PythonIsoTpConnection
from udsoncan.services import DiagnosticSessionControl, ECUReset

DEV_SECURITY_SECRET = b"AutoPlug development security secret"

# Diagnostic node numbers (the DBC's DiagNodeNumber).
ECUS = {
    "Engine": 0x03,
    "Pedals": 0x04,
    "Steering": 0x05,
    "Transmission": 0x06,
    "Cabin": 0x0A,
    "Console": 0x0B,
    "Differential": 0x0C,
    "Cruise": 0x0D,
    "ABS": 0x0E,
}
IDENTIFICATION = {0xF187: "part number", 0xF189: "software version", 0xF18C: "serial number",
                  0xF191: "hardware version"}
SLOT_ADDRESS = 0x0802_0000


class AllBytes(udsoncan.DidCodec):
    """A DID whose value is the rest of the response (variable-length text)."""

    def encode(self, value):
        return bytes(value)

    def decode(self, payload):
        return bytes(payload)

    def __len__(self):
        raise udsoncan.DidCodec.ReadAllRemainingData


def security_key(node):
    def algorithm(level, seed, params=None):
        return hmac.new(DEV_SECURITY_SECRET, bytes([node]) + bytes(seed), hashlib.sha512).digest()[:16]

    return algorithm


def client_for(bus, node):
    address = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=0x700 + node, rxid=0x780 + node)
    params = {
        "tx_padding": 0xCC,
        "tx_data_min_length": 8,
        "blocksize": 0,
        "stmin": 0,
        "max_frame_size": 4095,
        "rx_flowcontrol_timeout": 2000,
        "rx_consecutive_frame_timeout": 2000,
    }
    stack = isotp.CanStack(bus, address=address, params=params)
    config = dict(udsoncan.configs.default_client_config)
    config["data_identifiers"] = {did: AllBytes for did in IDENTIFICATION}
    config["security_algo"] = security_key(node)
    config["request_timeout"] = 30
    # Through socketcand the request leaves the client long before its last frame is on
    # the bus (the TCP relay queues it): the server's announced P2 of 50 ms would expire
    # before the ECU even has the request. Use generous client timing instead.
    config["use_server_timing"] = False
    config["p2_timeout"] = 5
    config["p2_star_timeout"] = 10
    return Client(PythonIsoTpConnection(stack), config=config)


def read_identification(bus):
    for name, node in ECUS.items():
        with client_for(bus, node) as client:
            values = {}
            for did in IDENTIFICATION:
                response = client.read_data_by_identifier(did)
                values[did] = response.service_data.values[did].decode("ascii")
                if not values[did]:
                    raise SystemExit(f"uds-check: {name}: DID {did:04X} is empty")
            print(f"  {name:<12} " + "  ".join(f"{did:04X}={values[did]}" for did in IDENTIFICATION))


def download(bus, node, image, expected_version):
    with client_for(bus, node) as client:
        client.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        client.change_session(DiagnosticSessionControl.Session.programmingSession)
        client.unlock_security_access(1)
        client.start_routine(0xFF00)  # erase the DFU slot (answers 0x78 while it works)
        location = udsoncan.MemoryLocation(address=SLOT_ADDRESS, memorysize=len(image),
                                           address_format=32, memorysize_format=32)
        response = client.request_download(location)
        block = response.service_data.max_length - 2
        started = time.monotonic()
        for i, offset in enumerate(range(0, len(image), block)):
            client.transfer_data((i + 1) % 256, image[offset:offset + block])
        client.request_transfer_exit()
        took = time.monotonic() - started
        client.start_routine(0xFF01)  # check: signature, ECU, version; marks it for the swap
        client.ecu_reset(ECUReset.ResetType.hardReset)
        print(f"  downloaded {len(image)} bytes in {len(range(0, len(image), block))} blocks "
              f"({took:.1f} s wall clock), checked, reset")
    # The bootloader swaps the slots (about 3 s of simulated flash time), then the new
    # software starts and confirms itself.
    deadline = time.monotonic() + 60
    while True:
        time.sleep(1.0)
        try:
            with client_for(bus, node) as client:
                client.set_config("request_timeout", 2)
                response = client.read_data_by_identifier(0xF189)
                version = response.service_data.values[0xF189].decode("ascii")
                break
        except (udsoncan.exceptions.TimeoutException, udsoncan.exceptions.NegativeResponseException):
            if time.monotonic() > deadline:
                raise SystemExit("uds-check: the ECU did not come back after the reset")
    print(f"  after the reset the ECU reports software version {version}")
    if version != expected_version:
        raise SystemExit(f"uds-check: expected version {expected_version}, the ECU reports {version}")


def main():
    if len(sys.argv) != 6:
        print(__doc__, file=sys.stderr)
        return 2
    host, port, image_path, node_name, expected = sys.argv[1:]
    node = ECUS.get(node_name)
    if node is None:
        print(f"uds-check: unknown ECU {node_name!r} (one of {', '.join(ECUS)})", file=sys.stderr)
        return 2
    image = open(image_path, "rb").read()
    bus = can.Bus(interface="socketcand", host=host, port=int(port), channel="can0")
    # The server starts sending frames to a client a moment after its raw-mode handshake
    # (so they cannot mix with the handshake's '< ok >'): let that pass before asking.
    time.sleep(0.3)
    try:
        print("identification of every ECU (udsoncan 0x22):")
        read_identification(bus)
        print(f"download to the {node_name} ECU (udsoncan 0x10 0x27 0x31 0x34 0x36 0x37 0x11):")
        download(bus, node, image, expected)
    finally:
        bus.shutdown()
    print("uds-check: udsoncan and can-isotp agree with the ECUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
