#!/usr/bin/env python3
"""Flash and static RAM use of the ECU firmwares, and where the flash goes.

Called by scripts/firmware-size after the release build, with the ELF files:

    firmware-size.py [--markdown] ELF...

Flash is what the image programs: the vector table, code, read-only data and the initial
values of .data. Static RAM is .data, .bss and .uninit (the defmt RTT buffer among them);
the stack is not static and is not counted.

The breakdown gives each crate's share of the code, from the DWARF line table: every
instruction is counted for the source file it was compiled from, so code inlined into a
caller counts for the crate that wrote it (a symbol-based count such as cargo-bloat's puts
it all on the caller, which hides most of an embedded image in the one async main task).
"core" is the core library's code inlined into everyone (slices, options, pointers,
integer arithmetic), "core::fmt" its formatting (reached by panic messages). Read-only data
has no line table and is one row.
"""
import collections
import os
import sys

try:
    from elftools.elf.elffile import ELFFile
except ImportError:
    sys.exit("firmware-size: needs pyelftools (scripts/setup-tests installs it into .venv)")

FLASH = (0x0800_0000, 0x0808_0000)  # 512 KiB on the F446RE
RAM = (0x2000_0000, 0x2002_0000)  # 128 KiB
# The budgets: 64 KiB of flash and 16 KiB of static RAM per firmware (the active
# slot, 128 KiB less the image header and signature, would take twice the flash).
FLASH_BUDGET = 64 * 1024
RAM_BUDGET = 16 * 1024
SHF_ALLOC = 0x2
# Rows of the breakdown: the largest crates, the rest summed.
TOP_CRATES = 16


def crate_of(path, cache={}):
    """The crate a source file belongs to: the package of the nearest Cargo.toml above it,
    the library under /rustc/<hash>/library/, or the package of a build script's output."""
    if path in cache:
        return cache[path]
    crate = None
    parts = path.split("/")
    if path.startswith("/rustc/") and "library" in parts:
        crate = parts[parts.index("library") + 1]
        if crate == "core" and ("fmt" in parts or "str" in parts):
            crate = "core::fmt"
    elif "build" in parts and "out" in parts:
        # target/<triple>/release/build/<package>-<hash>/out/<file>
        crate = parts[parts.index("out") - 1].rsplit("-", 1)[0]
    else:
        directory = os.path.dirname(path)
        while directory not in ("", "/") and crate is None:
            manifest = os.path.join(directory, "Cargo.toml")
            if os.path.exists(manifest):
                crate = package_name(manifest)
            directory = os.path.dirname(directory)
    cache[path] = crate or "(other)"
    return cache[path]


def package_name(manifest):
    in_package = False
    with open(manifest) as lines:
        for line in lines:
            line = line.strip()
            if line.startswith("["):
                in_package = line == "[package]"
            elif in_package and line.startswith("name") and "=" in line:
                return line.split("=", 1)[1].strip().strip('"')
    return None


def measure(path):
    """(flash, ram, {crate: bytes}) of one ELF file."""
    with open(path, "rb") as file:
        try:
            elf = ELFFile(file)
        except Exception as error:  # pyelftools raises its own and struct errors
            sys.exit(f"firmware-size: {path} is not an ELF file: {error}")
        if elf.elfclass != 32 or not elf.little_endian:
            sys.exit(f"firmware-size: {path} is not a 32-bit little-endian ELF file")
        flash = ram = 0
        shares = collections.Counter()
        for section in elf.iter_sections():
            size = section["sh_size"]
            if not (section["sh_flags"] & SHF_ALLOC) or not size:
                continue
            address = section["sh_addr"]
            if FLASH[0] <= address < FLASH[1]:
                flash += size
                if section.name != ".text":
                    shares["(read-only data)" if section.name == ".rodata" else f"({section.name})"] += size
            elif RAM[0] <= address < RAM[1]:
                ram += size
                if section.name == ".data":
                    flash += size  # its initial values are in the image too
                    shares["(initial values of .data)"] += size
        text = elf.get_section_by_name(".text")
        if text is not None:
            shares.update(code_by_crate(elf, path, text["sh_addr"], text["sh_addr"] + text["sh_size"]))
        return flash, ram, shares


def code_by_crate(elf, path, low, high):
    """Bytes of [low, high) per crate, by the DWARF line table."""
    shares = collections.Counter()
    if not elf.has_dwarf_info():
        shares["(no debug info)"] = high - low
        return shares
    dwarf = elf.get_dwarf_info()
    counted = 0
    for unit in dwarf.iter_CUs():
        program = dwarf.line_program_for_CU(unit)
        if program is None:
            continue
        header = program.header
        version = header["version"]
        top = unit.get_top_DIE().attributes.get("DW_AT_comp_dir")
        comp_dir = top.value.decode() if top else ""
        directories = [d.decode() if isinstance(d, bytes) else d for d in header["include_directory"]]
        files = header["file_entry"]

        def source(index):
            # DWARF 5 numbers files and directories from 0, earlier versions from 1.
            entry = files[index if version >= 5 else index - 1]
            directory_index = entry.dir_index
            if version >= 5:
                directory = directories[directory_index]
            else:
                directory = directories[directory_index - 1] if directory_index > 0 else comp_dir
            return os.path.normpath(os.path.join(comp_dir, directory, entry.name.decode()))

        previous = None
        for entry in program.get_entries():
            state = entry.state
            if state is None:
                continue
            if previous is not None and low <= previous.address < high and state.address > previous.address:
                size = min(state.address, high) - previous.address
                shares[crate_of(source(previous.file))] += size
                counted += size
            previous = None if state.end_sequence else state
    if high - low > counted:
        shares["(code without line info)"] += high - low - counted
    return shares


def main():
    args = sys.argv[1:]
    markdown = bool(args) and args[0] == "--markdown"
    binaries = args[1:] if markdown else args
    rows = []
    for binary in binaries:
        flash, ram, shares = measure(binary)
        rows.append((os.path.basename(binary), flash, ram, shares))

    def pct(used, budget):
        return f"{100 * used / budget:.0f} %"

    if markdown:
        print("| firmware | flash (B) | of 64 KiB | static RAM (B) | of 16 KiB |")
        print("|---|---:|---:|---:|---:|")
        for name, flash, ram, _ in rows:
            print(f"| {name} | {flash:,} | {pct(flash, FLASH_BUDGET)} | {ram:,} | {pct(ram, RAM_BUDGET)} |")
    else:
        print(f"{'firmware':<12} {'flash (B)':>10} {'of 64 KiB':>10} {'static RAM (B)':>15} {'of 16 KiB':>10}")
        for name, flash, ram, _ in rows:
            print(f"{name:<12} {flash:>10,} {pct(flash, FLASH_BUDGET):>10} {ram:>15,} {pct(ram, RAM_BUDGET):>10}")

    # The breakdown: one column per firmware, the crates that take most over all of them.
    total = collections.Counter()
    for *_, shares in rows:
        total.update(shares)
    top = [crate for crate, _ in total.most_common() if not crate.startswith("(")][:TOP_CRATES]
    others = [crate for crate in total if crate.startswith("(")]
    names = [name.removesuffix("-fw") for name, *_ in rows]
    print()
    print("Flash by crate (B; code by the DWARF line table, inlined code counted for its crate):")
    if markdown:
        print("| crate | " + " | ".join(names) + " |")
        print("|---|" + "---:|" * len(names))
    else:
        print(f"{'crate':<26}" + "".join(f"{n:>9}" for n in names))

    def line(label, values):
        if markdown:
            print(f"| {label} | " + " | ".join(f"{v:,}" for v in values) + " |")
        else:
            print(f"{label:<26}" + "".join(f"{v:>9,}" for v in values))

    own = [f"ecu-{name}" for name in names]
    line("(the ECU's own crate)", [shares[crate] for crate, (*_, shares) in zip(own, rows)])
    top = [crate for crate in top if crate not in own]
    for crate in top:
        line(crate, [shares[crate] for *_, shares in rows])
    listed = set(top) | set(others) | set(own)
    line("(other crates)", [sum(v for k, v in shares.items() if k not in listed) for *_, shares in rows])
    for label in sorted(others):
        line(label, [shares[label] for *_, shares in rows])

    over = [name for name, flash, ram, _ in rows if flash > FLASH_BUDGET or ram > RAM_BUDGET]
    if over:
        sys.exit(f"firmware-size: over budget (64 KiB of flash, 16 KiB of static RAM): {', '.join(over)}")


if __name__ == "__main__":
    main()
