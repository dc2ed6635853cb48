"""A little OpenEXR header surgery, in plain Python (Blender's Python has no EXR module).

dofray names its channels after Blender's default view layer (`ViewLayer.Combined.R`, ...), and
Blender loads a multilayer EXR into a render result by layer name. For a view layer with another
name the channels are renamed in the file's header: the channel list is rewritten and the
offset table shifted by the header's change in length (the pixel data does not move relative to
itself, and a common prefix keeps the channels' sorted order).
"""

import struct

MAGIC = 20000630
# Scan lines per chunk, by compression (OpenEXR's numLinesInBuffer).
LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}


def _cstr(data, pos):
    end = data.index(b"\0", pos)
    return data[pos:end], end + 1


def read_header(data):
    """[(name, type, value bytes, start, end)] of the attributes, and the header's end."""
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != MAGIC:
        raise ValueError("not an OpenEXR file")
    if version & 0x200 or version & 0x1000 or version & 0x800:
        raise ValueError("tiled, deep or multi-part EXR: not supported here")
    pos = 8
    attrs = []
    while data[pos] != 0:
        start = pos
        name, pos = _cstr(data, pos)
        typ, pos = _cstr(data, pos)
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        attrs.append((name, typ, data[pos:pos + size], start, pos + size))
        pos += size
    return attrs, pos + 1


def channel_names(path):
    with open(path, "rb") as f:
        data = f.read()
    attrs, _ = read_header(data)
    for name, typ, value, _, _ in attrs:
        if name == b"channels":
            return [c[0].decode() for c in _parse_chlist(value)]
    return []


def _parse_chlist(value):
    out, pos = [], 0
    while value[pos] != 0:
        name, pos = _cstr(value, pos)
        out.append((name, value[pos:pos + 16]))
        pos += 16
    return out


def rename_layer(path, old, new):
    """Renames channels `old.*` to `new.*` in the EXR at `path`, in place."""
    if old == new:
        return
    with open(path, "rb") as f:
        data = f.read()
    attrs, header_end = read_header(data)
    values = {a[0]: a for a in attrs}
    chl = values.get(b"channels")
    if chl is None:
        raise ValueError("EXR without a channel list")
    prefix_old, prefix_new = (old + ".").encode(), (new + ".").encode()
    chans = []
    for name, rest in _parse_chlist(chl[2]):
        if name.startswith(prefix_old):
            name = prefix_new + name[len(prefix_old):]
        chans.append((name, rest))
    if [c[0] for c in chans] != sorted(c[0] for c in chans):
        raise ValueError("renaming would change the channels' order")
    new_value = b"".join(n + b"\0" + r for n, r in chans) + b"\0"
    new_attr = b"channels\0chlist\0" + struct.pack("<i", len(new_value)) + new_value
    _, _, _, start, end = chl
    header = data[:start] + new_attr + data[end:header_end]
    delta = len(header) - header_end
    comp = values[b"compression"][2][0]
    ymin, ymax = struct.unpack_from("<iiii", values[b"dataWindow"][2], 0)[1::2]
    chunks = -(-(ymax - ymin + 1) // LINES_PER_CHUNK.get(comp, 1))
    offsets = struct.unpack_from(f"<{chunks}Q", data, header_end)
    table_end = header_end + 8 * chunks
    if min(offsets) < table_end:
        raise ValueError("unexpected offset table")
    table = struct.pack(f"<{chunks}Q", *(o + delta for o in offsets))
    with open(path, "wb") as f:
        f.write(header)
        f.write(table)
        f.write(data[table_end:])

