"""Variants of the real instrument files (copies modified in a temp dir) for the reader tests.

Each builder makes a file a user may have that the shipped examples are not: an Igor wave of
another version, a wave note with keys removed or renamed, a wave with other channels, a JPK
curve with a dwell segment or without force calibration. Byte-level edits keep everything
else of the real file as it was.
"""

from __future__ import annotations

import struct
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: offset of ``noteSize`` in a version-5 .ibw: version (h), checksum (h), wfmSize (l),
#: formulaSize (l); igor2 does not check the checksum
_NOTE_SIZE_OFFSET_V5 = 12


def ibw_with_note(src: Path, dst: Path, edit: Callable[[str], str]) -> Path:
    """Copy the version-5 wave ``src`` to ``dst`` with its wave note replaced by
    ``edit(note)`` (``\\r``-separated ``Key: value`` lines), the header's note size updated."""
    from igor2 import binarywave

    raw = src.read_bytes()
    order = "<" if raw[:2] == b"\x05\x00" else ">"
    assert struct.unpack(order + "h", raw[:2])[0] == 5, "version-5 waves only"
    note = bytes(binarywave.load(str(src))["wave"]["note"])
    start = raw.index(note)
    new = edit(note.decode("latin-1")).encode("latin-1")
    out = bytearray(raw[:start] + new + raw[start + len(note):])
    out[_NOTE_SIZE_OFFSET_V5:_NOTE_SIZE_OFFSET_V5 + 4] = struct.pack(order + "l", len(new))
    dst.write_bytes(bytes(out))
    return dst


def drop_note_keys(*keys: str) -> Callable[[str], str]:
    """An ``edit`` for `ibw_with_note` deleting the lines of ``keys``."""
    def edit(note: str) -> str:
        return "\r".join(line for line in note.split("\r")
                         if line.partition(":")[0].strip() not in keys)
    return edit


def set_note_keys(**values: str) -> Callable[[str], str]:
    """An ``edit`` for `ibw_with_note` replacing (or appending) ``Key: value`` lines."""
    def edit(note: str) -> str:
        lines = [line for line in note.split("\r")
                 if line.partition(":")[0].strip() not in values]
        return "\r".join([*lines, *(f"{k}: {v}" for k, v in values.items())])
    return edit


def ibw_version2(path: Path, values: np.ndarray, note: str = "SpringConstant: 2\r",
                 name: str = "Defl") -> Path:
    """A version-2 Igor wave (one channel, float32, no dimension labels), little-endian,
    laid out as igor2 reads it (BinHeader2 14 bytes, WaveHeader2 110, 16 bytes padding)."""
    data = np.asarray(values, "<f4")
    wave_header = struct.pack("<hI20shhI4s4sihddhhhddccIiI2sII", 2, 0,
                              name.encode().ljust(20, b"\0"), 0, 0, 0, b"m\0\0\0",
                              b"s\0\0\0", data.size, 0, 5e-4, 0.0, 0, 0, 0, 0.0, 0.0,
                              b"\0", b"\0", 0, 0, 0, b"\0\0", 0, 0)
    bin_header = struct.pack("<hiiih", 2, len(wave_header) + data.nbytes + 16,
                             len(note), 0, 0)
    path.write_bytes(bin_header + wave_header + data.tobytes() + b"\0" * 16 + note.encode())
    return path


def edited_wave(src: Path, *, drop: tuple[str, ...] = (),
                scale: dict[str, float] | None = None) -> dict[str, Any]:
    """``igor2.binarywave.load(src)`` of the real file with columns dropped and others
    multiplied (e.g. ``{"Defl": 1 / invols}``: the channel as the controller stores it in
    volts); returned for a monkeypatched ``binarywave.load``."""
    from igor2 import binarywave

    loaded = binarywave.load(str(src))
    wave = dict(loaded["wave"])
    labels = [b for b in wave["labels"][1]]
    names = [b.decode() for b in labels[1:]]
    keep = [i for i, n in enumerate(names) if n not in drop]
    data = np.asarray(wave["wData"], dtype=float)[:, keep].copy()
    for j, i in enumerate(keep):
        data[:, j] *= (scale or {}).get(names[i], 1.0)
    wave["wData"] = data
    wave["labels"] = [wave["labels"][0], [labels[0], *(labels[i + 1] for i in keep)]]
    return {**loaded, "wave": wave}


def jpk_edited(src: Path, dst: Path, edit: Callable[[str, bytes], bytes],
               skip: str | None = None) -> Path:
    """Copy the JPK zip ``src`` with every ``.properties`` member passed through ``edit``
    and the members whose name contains ``skip`` left out."""
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, "w") as out:
        for info in z.infolist():
            name = info.filename
            if skip is not None and skip in name:
                continue
            data = b"" if name.endswith("/") else z.read(name)
            out.writestr(name, edit(name, data) if name.endswith(".properties") else data)
    return dst


def jpk_with_dwell(src: Path, dst: Path) -> Path:
    """A JPK creep-compliance curve made of the two-segment ``src``: extend, a constant-force
    pause (a copy of the extend data), retract (the old segment 1, now segment 2)."""
    with zipfile.ZipFile(src) as z, zipfile.ZipFile(dst, "w") as out:
        names = [i.filename for i in z.infolist()]
        files = {n: b"" if n.endswith("/") else z.read(n) for n in names}
        for name in names:
            if not name.startswith("segments/1/"):
                out.writestr(name, files[name])
                continue
            out.writestr(name.replace("segments/1/", "segments/2/"), files[name])
            pause = files[name.replace("segments/1/", "segments/0/")]
            if name.endswith("segment-header.properties"):
                pause = pause.replace(b"settings.style=extend", b"settings.style=pause")
                pause = pause.replace(b"segment-settings.type=z-extend-force",
                                      b"segment-settings.type=constant-force-pause")
            out.writestr(name, pause)
    return dst


def nid_with_sweep_first(src: Path, dst: Path) -> Path:
    """The thermal-tune .nid with a 'Frequency sweep' group (amplitude in V over 170-190 kHz)
    put before the spectrum groups: header section added, its data placed before theirs.
    (nsfopen needs every data set of one length, so the sweep has the spectrum's.)"""
    raw = src.read_bytes()
    end = raw.index(b"\n\r\n\r")
    head = raw[:end].decode("latin-1")
    groups_old = ("GroupCount=2\r\nGr0-Name=Spectrum FFT\r\nGr0-ID=0\r\nGr0-Count=1\r\n"
                  "Gr1-Name=Spectrum Fit\r\nGr1-ID=0\r\nGr1-Count=1\r\n"
                  "Gr0-Ch0=DataSet-0:0\r\nGr1-Ch0=DataSet-1:0")
    groups_new = ("GroupCount=3\r\nGr0-Name=Frequency sweep\r\nGr0-ID=0\r\nGr0-Count=1\r\n"
                  "Gr1-Name=Spectrum FFT\r\nGr1-ID=0\r\nGr1-Count=1\r\n"
                  "Gr2-Name=Spectrum Fit\r\nGr2-ID=0\r\nGr2-Count=1\r\n"
                  "Gr0-Ch0=DataSet-2:0\r\nGr1-Ch0=DataSet-0:0\r\nGr2-Ch0=DataSet-1:0")
    assert groups_old in head
    points = int(head.split("[DataSet-0:0]")[1].split("Points=")[1].split("\r\n")[0])
    section = (f"[DataSet-2:0]\r\nVersion=2\r\nPoints={points}\r\nLines=1\r\n"
               "Frame=Frequency sweep\r\nCurLine=0\r\nDim0Name=Frequency\r\nDim0Unit=Hz\r\n"
               "Dim0Range=20000\r\nDim0Min=170000\r\nDim1Range=0\r\nDim1Min=0\r\n"
               "Dim2Name=Amplitude\r\nDim2Unit=V\r\nDim2Range=2\r\nDim2Min=-1\r\n"
               "SaveMode=Binary\r\nSaveBits=32\r\nSaveSign=Signed\r\nSaveOrder=Intel\r\n\r\n")
    head = head.replace(groups_old, groups_new).replace("[DataSet-0:0]",
                                                        section + "[DataSet-0:0]")
    body, tail = raw[end:], 2 * points * 4  # the two int32 spectra end the file
    sweep = np.linspace(-2.0**30, 2.0**30, points).astype("<i4").tobytes()
    dst.write_bytes(head.encode("latin-1") + body[:-tail] + sweep + body[-tail:])
    return dst
