#!/usr/bin/env python3
"""The client half of scripts/socketcand-check: python-can and cantools against the virtual
car's socketcand server (virtual-car run ... --socketcand HOST:PORT).

Two phases, run by scripts/socketcand-check around one run of the car:

  live  connects python-can's `socketcand` interface, receives frames for a while, decodes
        every one with cantools against the project DBC (lengths, signal ranges), sends one
        distinctive frame that is not in the catalogue, keeps listening to make sure it is
        not echoed back, and writes what it saw to a JSON state file;
  log   after the car has finished, reads its bus.log (candump format) and checks that the
        sent frame is on the bus exactly once, then prints the PASS/FAIL summary of both
        phases.

Each phase prints one line per check and exits 1 when a check failed (2 when it could not
run at all). Every failure says what was expected and what was seen.
"""

import argparse
import json
import logging
import sys
import time
from collections import Counter
from pathlib import Path

import can
import cantools

PROBE_ID = 0x6AB
PROBE_DATA = bytes.fromhex("DEADBEEF01020304")
PROBE_TEXT = f"{PROBE_ID:03X}#{PROBE_DATA.hex().upper()}"  # as candump writes it
EXAMPLES = 5  # failing frames quoted per check


def frame_text(msg):
    """A python-can message the way candump writes it (`6AB#DEADBEEF01020304`)."""
    width = 8 if msg.is_extended_id else 3
    return f"{msg.arbitration_id:0{width}X}#{bytes(msg.data).hex().upper()}"


class Report:
    """Check results, printed as they come."""

    def __init__(self):
        self.failures = []

    def ok(self, text):
        print(f"  ok    {text}", flush=True)

    def fail(self, what, expected, seen, examples=()):
        self.failures.append(what)
        print(f"  FAIL  {what}: expected {expected}; saw {seen}", flush=True)
        for example in list(examples)[:EXAMPLES]:
            print(f"          {example}", flush=True)

    def check(self, condition, what, expected, seen, examples=()):
        if condition:
            self.ok(f"{what} ({seen})")
        else:
            self.fail(what, expected, seen, examples)
        return condition


class PythonCanWarnings(logging.Handler):
    """Collects python-can's socketcand warnings. "Got incomplete message" is normal (a
    message split across two recv() calls); anything else there means python-can could not
    parse what the server sent, or dropped it."""

    BENIGN = ("Got incomplete message",)

    def __init__(self):
        super().__init__(logging.WARNING)
        self.problems = 0
        self.examples = []
        self.benign = 0

    def emit(self, record):
        text = record.getMessage()
        if text.startswith(self.BENIGN):
            self.benign += 1
        else:
            self.problems += 1
            if len(self.examples) < EXAMPLES:
                self.examples.append(text)


def load_dbc(path, report):
    try:
        return cantools.database.load_file(str(path))
    except Exception as e:  # noqa: BLE001 - any load error is a failure to report
        report.fail("load the DBC", f"a readable DBC at {path}", f"{type(e).__name__}: {e}")
        return None


def port_listening(host, port):
    """Whether something listens on host:port, from /proc/net/tcp (without connecting: a
    probe connection would be a client of the server). None when this cannot be told."""
    try:
        lines = Path("/proc/net/tcp").read_text().splitlines()[1:]
    except OSError:
        return None
    want_ip = None
    if host.count(".") == 3:  # /proc/net/tcp writes 127.0.0.1 as 0100007F
        want_ip = "".join(f"{int(b):02X}" for b in reversed(host.split(".")))
    for line in lines:
        fields = line.split()
        if len(fields) < 4 or fields[3] != "0A":  # 0A = LISTEN
            continue
        ip, _, p = fields[1].partition(":")
        if int(p, 16) == port and (want_ip is None or ip in (want_ip, "00000000")):
            return True
    return False


def connect(host, port, channel, timeout_s, report):
    """Opens the python-can bus, retrying while the server starts. Returns (bus, attempts)."""
    start = time.monotonic()
    deadline = start + timeout_s
    # python-can retries a refused connect by itself for 10 s in a busy loop that logs a
    # warning per try, so only call it once the port listens.
    while port_listening(host, port) is False:
        if time.monotonic() >= deadline:
            report.fail(
                "connect",
                f"a socketcand server listening on {host}:{port} within {timeout_s:g} s",
                "nothing listening there (/proc/net/tcp)",
            )
            return None, 0
        time.sleep(0.05)
    attempts = 0
    last_error = None
    while True:
        attempts += 1
        try:
            bus = can.Bus(
                interface="socketcand", host=host, port=port, channel=channel, tcp_tune=True
            )
            report.ok(
                f"connected python-can {can.__version__} (socketcand, {channel}) to {host}:{port} "
                f"after {attempts} attempt(s), {time.monotonic() - start:.2f} s"
            )
            return bus, attempts
        except can.CanError as e:
            # The handshake itself went wrong (e.g. a frame glued to the rawmode '< ok >'):
            # a protocol fault of the server, not something to retry away.
            report.fail(
                "socketcand handshake",
                "'< hi >', then '< ok >' to open and to rawmode, each as its own message",
                f"python-can: {e}",
            )
            return None, attempts
        except OSError as e:  # refused, reset, python-can's TimeoutError
            last_error = e
        if time.monotonic() >= deadline:
            report.fail(
                "connect",
                f"a socketcand server on {host}:{port} within {timeout_s:g} s",
                f"{attempts} failed attempt(s), last: {type(last_error).__name__}: {last_error}",
            )
            return None, attempts
        time.sleep(0.2)


def frame_problems(msg, catalogue, max_speed_kmh):
    """What is wrong with a received frame (empty when it is a good catalogue frame)."""
    text = frame_text(msg)
    if msg.is_error_frame:
        return [f"{text}: an error frame"]
    if msg.is_extended_id:
        return [f"{text}: extended (29-bit) identifier; the catalogue uses 11-bit ones"]
    if msg.is_remote_frame or msg.is_fd:
        return [f"{text}: remote or CAN FD frame"]
    message = catalogue.get(msg.arbitration_id)
    if message is None:
        return [f"{text}: identifier 0x{msg.arbitration_id:03X} is not in the catalogue"]
    if len(msg.data) != message.length:
        return [
            f"{text}: {message.name} must have {message.length} data bytes, has {len(msg.data)}"
        ]
    try:
        values = message.decode(bytes(msg.data), decode_choices=False)
    except Exception as e:  # noqa: BLE001 - cantools raises several error types
        return [f"{text}: cantools cannot decode it as {message.name}: {e}"]
    problems = []
    for signal in message.signals:
        value = values[signal.name]
        tolerance = abs(signal.scale) * 1e-6
        lo = signal.minimum if signal.minimum is not None else float("-inf")
        hi = signal.maximum if signal.maximum is not None else float("inf")
        if not lo - tolerance <= value <= hi + tolerance:
            problems.append(
                f"{text}: {message.name}.{signal.name} = {value:g} is outside the DBC range "
                f"{lo:g}..{hi:g}"
            )
        if signal.unit == "km/h" and value > max_speed_kmh:
            problems.append(
                f"{text}: {message.name}.{signal.name} = {value:g} km/h, implausible for this "
                f"scenario (at most {max_speed_kmh:g} km/h)"
            )
    return problems


def receive(bus, seconds, catalogue, max_speed_kmh, seen):
    """Receives for `seconds`, collecting into `seen`."""
    deadline = time.monotonic() + seconds
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return
        msg = bus.recv(timeout=left)
        if msg is None:
            continue
        seen["frames"] += 1
        seen["ids"][msg.arbitration_id] += 1
        if seen["last_ts"] is not None and msg.timestamp < seen["last_ts"]:
            seen["backwards"].append(
                f"{frame_text(msg)} at {msg.timestamp:.6f} s after one at {seen['last_ts']:.6f} s"
            )
        seen["last_ts"] = msg.timestamp
        if msg.arbitration_id == PROBE_ID and not msg.is_extended_id:
            seen["echoes"].append(f"{frame_text(msg)} at {msg.timestamp:.6f} s")
            continue
        problems = frame_problems(msg, catalogue, max_speed_kmh)
        if problems:
            seen["bad"] += 1
            seen["problems"].extend(problems[: max(0, EXAMPLES - len(seen["problems"]))])
        else:
            seen["decoded"] += 1


def live(args):
    report = Report()
    state = {"connected": False, "sent": False, "failures": []}

    def finish(code):
        state["failures"] = report.failures
        Path(args.state).write_text(json.dumps(state, indent=1))
        return code

    db = load_dbc(args.dbc, report)
    if db is None:
        return finish(2)
    catalogue = {m.frame_id: m for m in db.messages}
    if not report.check(
        PROBE_ID not in catalogue,
        f"probe identifier 0x{PROBE_ID:03X} is outside the catalogue",
        "an identifier no ECU sends",
        (
            f"{len(catalogue)} catalogue IDs"
            if PROBE_ID not in catalogue
            else f"it is {catalogue[PROBE_ID].name}"
        ),
    ):
        return finish(2)

    warnings = PythonCanWarnings()
    can_log = logging.getLogger("can.interfaces.socketcand.socketcand")
    can_log.addHandler(warnings)
    can_log.propagate = False

    bus, _ = connect(args.host, args.port, args.channel, args.connect_timeout, report)
    if bus is None:
        return finish(2)
    state["connected"] = True
    seen = {
        "frames": 0,
        "decoded": 0,
        "bad": 0,
        "ids": Counter(),
        "problems": [],
        "echoes": [],
        "backwards": [],
        "last_ts": None,
    }
    try:
        started = time.monotonic()
        receive(bus, args.receive_s, catalogue, args.max_speed_kmh, seen)
        before = dict(seen, ids=Counter(seen["ids"]))
        rate = before["frames"] / max(time.monotonic() - started, 1e-9)
        ids = sorted(before["ids"])
        report.check(
            before["frames"] >= args.min_frames,
            f"received frames in {args.receive_s:g} s",
            f"at least {args.min_frames}",
            f"{before['frames']} frames, {rate:.0f}/s",
        )
        report.check(
            len(ids) >= args.min_ids and all(i in catalogue for i in ids),
            "received several catalogue IDs",
            f"at least {args.min_ids} distinct IDs, all in the catalogue",
            f"{len(ids)} IDs: " + " ".join(f"{i:03X}" for i in ids),
        )

        probe = can.Message(arbitration_id=PROBE_ID, is_extended_id=False, data=PROBE_DATA)
        try:
            bus.send(probe)
            state["sent"] = True
            state["last_ts_before_send"] = seen["last_ts"]
            report.ok(f"sent {PROBE_TEXT} after the frame stamped {seen['last_ts']} s")
        except Exception as e:  # noqa: BLE001
            report.fail(
                "send the probe frame",
                f"python-can to send {PROBE_TEXT}",
                f"{type(e).__name__}: {e}",
            )

        after_from = seen["frames"]
        receive(bus, args.echo_s, catalogue, args.max_speed_kmh, seen)
        after = seen["frames"] - after_from
        report.check(
            after > 0,
            f"frames keep coming after the send ({args.echo_s:g} s)",
            "more frames",
            f"{after} frames",
        )
    finally:
        bus.shutdown()

    report.check(
        seen["bad"] == 0,
        "every received frame decodes against the DBC (length, signal ranges, plausible speeds)",
        "0 bad frames",
        f"{seen['decoded']} decoded, {seen['bad']} bad",
        seen["problems"],
    )
    report.check(
        not seen["echoes"],
        "python-can did not receive its own frame back",
        f"no {PROBE_TEXT} among the received frames",
        f"{len(seen['echoes'])} echo(es)" if seen["echoes"] else f"none in {seen['frames']} frames",
        seen["echoes"],
    )
    report.check(
        not seen["backwards"],
        "frame timestamps never go backwards",
        "non-decreasing timestamps",
        f"{len(seen['backwards'])} going backwards" if seen["backwards"] else "in order",
        seen["backwards"],
    )
    report.check(
        not warnings.problems,
        "python-can parsed every server message",
        "no python-can warnings (other than messages split across reads)",
        f"{warnings.problems} warning(s), {warnings.benign} split message(s)",
        warnings.examples,
    )
    state.update(
        frames=seen["frames"],
        decoded=seen["decoded"],
        bad=seen["bad"],
        ids=len(seen["ids"]),
        echoes=len(seen["echoes"]),
    )
    return finish(1 if report.failures else 0)


def parse_candump(path):
    """(line number, seconds, body) per frame of a candump log; body is `ID#DATA`."""
    records = []
    with open(path, encoding="ascii", errors="replace") as f:
        for number, line in enumerate(f, 1):
            parts = line.split()
            if not parts:
                continue
            try:
                stamp = parts[0]
                if len(parts) not in (3, 4) or not (stamp.startswith("(") and stamp.endswith(")")):
                    raise ValueError
                can_id, data = parts[2].split("#")
                int(can_id, 16), bytes.fromhex(data)
                records.append((number, float(stamp[1:-1]), parts[2].upper()))
            except ValueError:
                raise ValueError(f"{path}:{number}: not a candump line: {line.strip()!r}") from None
    return records


def log(args):
    report = Report()
    try:
        state = json.loads(Path(args.state).read_text())
    except (OSError, ValueError) as e:
        state = {"failures": [f"live phase left no state ({e})"]}
    db = load_dbc(args.dbc, report)
    catalogue = {m.frame_id for m in db.messages} if db else set()
    try:
        records = parse_candump(args.bus_log)
    except (OSError, ValueError) as e:
        report.fail("read bus.log", f"a candump log at {args.bus_log}", f"{type(e).__name__}: {e}")
        records = None
    if records is not None:
        probes = [r for r in records if int(r[2].split("#")[0], 16) == PROBE_ID]
        exact = [r for r in probes if r[2] == PROBE_TEXT]
        report.check(
            len(probes) == 1 and len(exact) == 1,
            "bus.log holds the sent frame exactly once",
            f"one {PROBE_TEXT} line and no other 0x{PROBE_ID:03X} frame",
            f"{len(exact)} exact, {len(probes)} with ID {PROBE_ID:03X}, "
            f"among {len(records)} frames",
            [f"line {n}: ({t:.6f}) {b}" for n, t, b in probes],
        )
        last = state.get("last_ts_before_send")
        if len(exact) == 1 and last is not None:
            report.check(
                exact[0][1] > last,
                "the sent frame is on the bus after the frames received before sending",
                f"a time after {last:.6f} s",
                f"{exact[0][1]:.6f} s (line {exact[0][0]})",
            )
        known = catalogue | {PROBE_ID}
        strangers = [r for r in records if int(r[2].split("#")[0], 16) not in known]
        report.check(
            not strangers and db is not None,
            "every other bus.log frame has a catalogue ID",
            "only catalogue IDs besides the probe",
            (
                f"{len(strangers)} other frame(s)"
                if strangers
                else f"{len(records) - len(probes)} catalogue frames"
            ),
            [f"line {n}: ({t:.6f}) {b}" for n, t, b in strangers],
        )

    failures = list(state.get("failures", [])) + report.failures
    counts = (
        f"received {state.get('frames', 0)} frames of {state.get('ids', 0)} IDs, "
        f"{state.get('decoded', 0)} decoded, {state.get('bad', 0)} bad, "
        f"{state.get('echoes', 0)} own-frame echoes; sent {1 if state.get('sent') else 0} frame; "
        + (f"bus.log: {len(records)} frames" if records is not None else "bus.log unreadable")
    )
    if failures:
        print(f"socketcand-check: FAIL ({len(failures)} failed: {'; '.join(failures)}) - {counts}")
        return 1
    print(f"socketcand-check: PASS - {counts}")
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dbc", required=True, help="the project DBC")
    parser.add_argument(
        "--state", required=True, help="JSON file passed from the live to the log phase"
    )
    sub = parser.add_subparsers(dest="phase", required=True)
    p = sub.add_parser("live", help="connect, receive, decode, send")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--channel", default="can0")
    p.add_argument(
        "--connect-timeout", type=float, default=5.0, help="seconds to retry the connect"
    )
    p.add_argument("--receive-s", type=float, default=2.0, help="seconds to receive before sending")
    p.add_argument(
        "--echo-s", type=float, default=1.0, help="seconds to keep receiving after sending"
    )
    p.add_argument("--min-frames", type=int, default=100)
    p.add_argument("--min-ids", type=int, default=8)
    p.add_argument(
        "--max-speed-kmh", type=float, default=255.0, help="plausibility bound on km/h signals"
    )
    p = sub.add_parser("log", help="check bus.log after the run and print the summary")
    p.add_argument("--bus-log", required=True)
    args = parser.parse_args()
    return live(args) if args.phase == "live" else log(args)


if __name__ == "__main__":
    sys.exit(main())
