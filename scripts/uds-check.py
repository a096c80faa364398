#!/usr/bin/env python3
"""An independent UDS client against the running virtual car: udsoncan over can-isotp over
python-can's socketcand interface. It reads the identification DIDs (F187 part number,
F189 software version, F18C serial number, F191 hardware version) of all nine ECUs, then
reads which image slot the ECU runs (DID F1A0), picks the image for the other slot from a
release (`autoplug image build` with one payload per slot: two signed images back to back),
runs a complete download of it (programming session, security access, erase,
RequestDownload, TransferData, RequestTransferExit, check, reset) and reads the new software
version and slot back.

    scripts/uds-check.py HOST PORT RELEASE NODE EXPECTED_VERSION

Exit status 0 when everything answered as the standard says; the failing step otherwise.
The security secret is the development one of the project (autoplug_uds::DEV_SECURITY_SECRET):
a tester has to be configured with the secret its ECUs use.
"""

import hashlib
import hmac
import struct
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
# The image slots of the F446RE (autoplug_flash::SLOT_A, SLOT_B): sectors 5 and 6.
SLOTS = {0: ("A", 0x0802_0000), 1: ("B", 0x0804_0000)}
BOOT_SLOT_DID = 0xF1A0
BOOT_STATES = {0: "confirmed", 1: "on trial", 2: "reverted"}
# The image format (shared/image): a 512-byte header, the payload, a 64-byte signature;
# the header holds the payload length at offset 24 and the load address at offset 28.
HEADER_LEN = 512
SIGNATURE_LEN = 64


def split_release(data):
    """The images of a release file, each as (load address, bytes)."""
    images = []
    while data:
        if len(data) < HEADER_LEN or data[:8] != b"APLGIMG1":
            raise SystemExit(f"uds-check: image {len(images) + 1} of the release has no image header")
        payload_len, load_address = struct.unpack_from("<II", data, 24)
        length = HEADER_LEN + payload_len + SIGNATURE_LEN
        if length > len(data):
            raise SystemExit(f"uds-check: image {len(images) + 1} of the release is cut short")
        images.append((load_address, data[:length]))
        data = data[length:]
    return images


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
    config["data_identifiers"] = {did: AllBytes for did in [*IDENTIFICATION, BOOT_SLOT_DID]}
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


def boot_slot(client):
    """(slot number, state number) from DID F1A0."""
    response = client.read_data_by_identifier(BOOT_SLOT_DID)
    value = response.service_data.values[BOOT_SLOT_DID]
    if len(value) != 2 or value[0] not in SLOTS or value[1] not in BOOT_STATES:
        raise SystemExit(f"uds-check: DID F1A0 answered {value.hex()}: not a slot and a state")
    return value[0], value[1]


def download(bus, node, release, expected_version):
    with client_for(bus, node) as client:
        running, state = boot_slot(client)
        target = 1 - running
        letter, slot_address = SLOTS[target]
        print(f"  the ECU runs slot {SLOTS[running][0]} ({BOOT_STATES[state]}): "
              f"the download goes to slot {letter}")
        chosen = [image for load, image in release if load == slot_address + HEADER_LEN]
        if not chosen:
            raise SystemExit(f"uds-check: the release has no image linked for slot {letter}")
        image = chosen[0]
        client.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        client.change_session(DiagnosticSessionControl.Session.programmingSession)
        client.unlock_security_access(1)
        client.start_routine(0xFF00)  # erase the slot not running (answers 0x78 while it works)
        location = udsoncan.MemoryLocation(address=slot_address, memorysize=len(image),
                                           address_format=32, memorysize_format=32)
        response = client.request_download(location)
        block = response.service_data.max_length - 2
        started = time.monotonic()
        for i, offset in enumerate(range(0, len(image), block)):
            client.transfer_data((i + 1) % 256, image[offset:offset + block])
        client.request_transfer_exit()
        took = time.monotonic() - started
        client.start_routine(0xFF01)  # check: signature, ECU, version; marks it for a trial
        client.ecu_reset(ECUReset.ResetType.hardReset)
        print(f"  downloaded {len(image)} bytes in {len(range(0, len(image), block))} blocks "
              f"({took:.1f} s wall clock), checked, reset")
    # The bootloader starts the new slot on trial (one record written), and the new
    # software confirms itself after its self-test.
    deadline = time.monotonic() + 60
    while True:
        time.sleep(1.0)
        try:
            with client_for(bus, node) as client:
                client.set_config("request_timeout", 2)
                response = client.read_data_by_identifier(0xF189)
                version = response.service_data.values[0xF189].decode("ascii")
                running, state = boot_slot(client)
                break
        except (udsoncan.exceptions.TimeoutException, udsoncan.exceptions.NegativeResponseException):
            if time.monotonic() > deadline:
                raise SystemExit("uds-check: the ECU did not come back after the reset")
    print(f"  after the reset the ECU reports software version {version}, "
          f"running slot {SLOTS[running][0]} ({BOOT_STATES[state]})")
    if version != expected_version:
        raise SystemExit(f"uds-check: expected version {expected_version}, the ECU reports {version}")
    if running != target:
        raise SystemExit(f"uds-check: the ECU runs slot {SLOTS[running][0]}, not the new slot {letter}")


def main():
    if len(sys.argv) != 6:
        print(__doc__, file=sys.stderr)
        return 2
    host, port, image_path, node_name, expected = sys.argv[1:]
    node = ECUS.get(node_name)
    if node is None:
        print(f"uds-check: unknown ECU {node_name!r} (one of {', '.join(ECUS)})", file=sys.stderr)
        return 2
    release = split_release(open(image_path, "rb").read())
    bus = can.Bus(interface="socketcand", host=host, port=int(port), channel="can0")
    # The server starts sending frames to a client a moment after its raw-mode handshake
    # (so they cannot mix with the handshake's '< ok >'): let that pass before asking.
    time.sleep(0.3)
    try:
        print("identification of every ECU (udsoncan 0x22):")
        read_identification(bus)
        print(f"download to the {node_name} ECU (udsoncan 0x10 0x27 0x31 0x34 0x36 0x37 0x11):")
        download(bus, node, release, expected)
    finally:
        bus.shutdown()
    print("uds-check: udsoncan and can-isotp agree with the ECUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
