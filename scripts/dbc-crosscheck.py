#!/usr/bin/env python3
"""Checks the generated CAN codec against cantools, an independent reader of the same DBC.

    cargo run -q -p autoplug-can --example export_vectors > target/can-vectors.jsonl
    python3 scripts/dbc-crosscheck.py shared/can/autoplug.dbc target/can-vectors.jsonl

The vectors file holds what the codec believes (layouts) and what it produces (frames).
For every message this checks that cantools reads the DBC the same way (identifier,
length, period, senders, and each signal's bits, sign, factor, offset, range, unit,
receivers, value table, start value and VSS path), that every frame the codec encoded decodes in
cantools to the same raw values and to the same physical values (to a thousandth of a
quantisation step: the codec computes in f32 for the MCU, cantools in f64), and that
cantools encodes those values back to the very same bytes. Exits non-zero, naming each
disagreement, if anything differs or if any catalogue message has no vectors.
"""

import json
import sys

import cantools


def main() -> int:
    if len(sys.argv) != 3:
        print(f"usage: {sys.argv[0]} DBC VECTORS.jsonl", file=sys.stderr)
        return 2
    dbc_path, vectors_path = sys.argv[1], sys.argv[2]
    try:
        db = cantools.database.load_file(dbc_path, strict=True)
    except Exception as e:  # cantools raises several unrelated types
        print(f"cantools cannot read {dbc_path}: {e}", file=sys.stderr)
        return 1

    problems: list[str] = []
    layouts: dict[str, dict] = {}
    diag_nodes: dict[str, dict] = {}
    functional_id = None
    frames_checked = 0
    values_checked = 0

    def problem(text: str) -> None:
        if len(problems) < 50:
            print(f"MISMATCH {text}", file=sys.stderr)
        problems.append(text)

    with open(vectors_path, encoding="utf-8") as f:
        for line_no, line in enumerate(f, 1):
            try:
                entry = json.loads(line)
            except json.JSONDecodeError as e:
                print(f"{vectors_path}:{line_no}: not JSON: {e}", file=sys.stderr)
                return 1
            if entry["kind"] == "layout":
                layouts[entry["message"]] = entry
                check_layout(db, entry, problem)
            elif entry["kind"] == "frame":
                values_checked += check_frame(db, layouts, entry, problem)
                frames_checked += 1
            elif entry["kind"] == "diag":
                diag_nodes[entry["node"]] = entry
            elif entry["kind"] == "functional":
                functional_id = entry["id"]
            else:
                print(f"{vectors_path}:{line_no}: unknown kind {entry['kind']!r}", file=sys.stderr)
                return 1

    diag_checked = check_diagnostics(db, diag_nodes, functional_id, problem)
    ours = set(layouts)
    theirs = {m.name for m in db.messages if diag_kind(m) == "None"}
    for name in sorted(theirs - ours):
        problem(f"{name}: in the DBC (cantools) but not in the codec's vectors")
    for name in sorted(ours - theirs):
        problem(f"{name}: in the codec but not in the DBC (cantools)")

    if problems:
        print(f"cantools cross-check FAILED: {len(problems)} disagreements", file=sys.stderr)
        return 1
    print(
        f"cantools cross-check: {len(ours)} of {len(theirs)} messages, {frames_checked} frames, "
        f"{values_checked} signal values, {diag_checked} diagnostic identifiers: "
        "codec and cantools agree"
    )
    return 0


def diag_kind(message) -> str:
    """The message attribute DiagKind as cantools reads it ("None" for application messages)."""
    attribute = message.dbc.attributes.get("DiagKind") if message.dbc else None
    if attribute is None:
        return "None"
    value = attribute.value
    choices = attribute.definition.choices
    return choices[value] if isinstance(value, int) else value


def check_diagnostics(db, diag_nodes: dict, functional_id, problem) -> int:
    """Every DiagKind message in the DBC is where the codec says it is, and vice versa."""
    expected = {}
    for node, entry in diag_nodes.items():
        for field, kind in (("request", "PhysicalRequest"), ("response", "PhysicalResponse"),
                            ("obd_response", "ObdResponse")):
            if entry[field] is not None:
                expected[entry[field]] = (kind, node)
    if functional_id is not None:
        expected[functional_id] = ("FunctionalRequest", None)
    found = {}
    for m in db.messages:
        kind = diag_kind(m)
        if kind == "None":
            continue
        if kind == "PhysicalRequest":
            owner = next(iter(m.receivers), None) if len(m.receivers) == 1 else None
        elif kind == "FunctionalRequest":
            owner = None
        else:
            owner = m.senders[0] if m.senders else None
        found[m.frame_id] = (kind, owner)
        if m.length != 8:
            problem(f"{m.name}: diagnostic message of {m.length} bytes, not 8")
    for frame_id in sorted(set(expected) | set(found)):
        if expected.get(frame_id) != found.get(frame_id):
            problem(f"diagnostic identifier 0x{frame_id:03X}: codec says {expected.get(frame_id)}, "
                    f"cantools reads {found.get(frame_id)}")
    return len(found)


def check_layout(db, entry: dict, problem) -> None:
    name = entry["message"]
    try:
        msg = db.get_message_by_name(name)
    except KeyError:
        problem(f"{name}: cantools has no such message")
        return
    expect = {
        "identifier": (entry["id"], msg.frame_id),
        "extended": (False, msg.is_extended_frame),
        "length": (entry["dlc"], msg.length),
        "cycle time": (entry["cycle_time_ms"], msg.cycle_time),
        "senders": (entry["senders"], list(msg.senders)),
        "signal names": ([s["name"] for s in entry["signals"]], [s.name for s in msg.signals]),
    }
    for what, (a, b) in expect.items():
        if a != b:
            problem(f"{name}: {what} codec={a!r} cantools={b!r}")
    for ours in entry["signals"]:
        try:
            sig = msg.get_signal_by_name(ours["name"])
        except KeyError:
            continue  # reported through the signal names above
        where = f"{name}.{ours['name']}"
        step = abs(ours["factor"])
        checks = {
            "start bit": (ours["start_bit"], sig.start),
            "length": (ours["length"], sig.length),
            "byte order": ("little_endian", sig.byte_order),
            "signed": (ours["signed"], sig.is_signed),
            "factor": (ours["factor"], sig.scale),
            "offset": (ours["offset"], sig.offset),
            "unit": (ours["unit"] or None, sig.unit or None),
            "receivers": (ours["receivers"], list(sig.receivers)),
            "value table": (
                {int(v): t for v, t in ours["values"]},
                {int(v): str(t) for v, t in (sig.choices or {}).items()},
            ),
            "start value (raw)": (
                ours["start_raw"],
                0 if sig.raw_initial is None else int(sig.raw_initial),
            ),
            "VSS path (attribute VssPath)": (
                ours["vss"],
                sig.dbc.attributes["VssPath"].value if sig.dbc and "VssPath" in sig.dbc.attributes else "",
            ),
        }
        for what, (a, b) in checks.items():
            if a != b:
                problem(f"{where}: {what} codec={a!r} cantools={b!r}")
        for what, a, b in (
            ("minimum", ours["physical_min"], sig.minimum),
            ("maximum", ours["physical_max"], sig.maximum),
        ):
            if b is None or abs(a - b) > 1e-3 * step:
                problem(f"{where}: {what} codec={a!r} cantools={b!r}")


def check_frame(db, layouts: dict, entry: dict, problem) -> int:
    name = entry["message"]
    where = f"{name} [{entry['why']}] data {entry['data']}"
    msg = db.get_message_by_frame_id(entry["id"])
    data = bytes.fromhex(entry["data"])
    raw = msg.decode(data, decode_choices=False, scaling=False)
    physical = msg.decode(data, decode_choices=False, scaling=True)
    steps = {s["name"]: abs(s["factor"]) for s in layouts[name]["signals"]}
    count = 0
    for signal, ours in entry["raw"].items():
        if raw.get(signal) != ours:
            problem(f"{where}: {signal} raw codec={ours} cantools={raw.get(signal)}")
        theirs = physical.get(signal)
        mine = entry["physical"][signal]
        if theirs is None or abs(float(theirs) - mine) > 1e-3 * steps[signal]:
            problem(f"{where}: {signal} physical codec={mine} cantools={theirs}")
        count += 1
    # cantools must produce the same bytes from the codec's decoded values.
    again = msg.encode(entry["physical"], scaling=True, strict=False, padding=False)
    if again != data:
        problem(f"{where}: cantools encodes the decoded values as {again.hex().upper()}")
    return count


if __name__ == "__main__":
    sys.exit(main())
