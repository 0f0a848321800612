"""The loadable bytes of an ELF32 little-endian ARM image, as a flash programmer sees them.

Reads the ELF header and the program headers (System V ABI, ELF32): every PT_LOAD segment
contributes its file bytes at its physical (load) address, which is where a programmer writes
them: .text at 0x08000000, and the initial values of .data after it in flash (the start-up
code copies them to RAM). Segments with no file bytes (.bss, the stack reserve) load nothing.
"""

import struct

PT_LOAD = 1
EM_ARM = 40


class ElfError(Exception):
    pass


def load_segments(path):
    """[(physical address, bytes)] of the PT_LOAD segments with file contents."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF":
        raise ElfError(f"{path}: not an ELF file")
    if data[4] != 1 or data[5] != 1:
        raise ElfError(f"{path}: not ELF32 little-endian")
    (e_machine,) = struct.unpack_from("<H", data, 18)
    if e_machine != EM_ARM:
        raise ElfError(f"{path}: machine {e_machine}, not ARM")
    e_phoff, = struct.unpack_from("<I", data, 28)
    e_phentsize, e_phnum = struct.unpack_from("<HH", data, 42)
    segments = []
    for i in range(e_phnum):
        p_type, p_offset, _vaddr, p_paddr, p_filesz, _memsz, _flags, _align = struct.unpack_from(
            "<8I", data, e_phoff + i * e_phentsize)
        if p_type == PT_LOAD and p_filesz > 0:
            segments.append((p_paddr, data[p_offset:p_offset + p_filesz]))
    if not segments:
        raise ElfError(f"{path}: no loadable segment")
    return segments
