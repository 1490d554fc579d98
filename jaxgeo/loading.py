"""Reading mesh files: `load_mesh` (OBJ, PLY, STL, OFF, … through trimesh).

Before trimesh parses a file, its header's counts are checked against what it
holds (trimesh would read a truncated file as a smaller mesh, or garbage), text is
made valid UTF-8, and an OBJ face index 0 is refused; after, vertices at equal
positions are merged (`jaxgeo._merge`) and, on request, the mesh is repaired
(`jaxgeo.repair_mesh`) before `Mesh` validates it.
"""

from __future__ import annotations

import io
import logging
import os
import re
import warnings
from typing import Literal

import numpy as np
import trimesh

from ._errors import JaxgeoError
from ._merge import merge_coincident
from ._mesh_checks import fail
from ._stacklevel import caller_stacklevel
from .mesh import Mesh
from .repair import repair_mesh


def load_mesh(
    path: str | os.PathLike,
    *,
    merge_vertices: bool = True,
    repair: bool | Literal["split", "remove"] = False,
) -> Mesh:
    """Read a triangle mesh file (OBJ, PLY, STL, OFF, … anything trimesh reads).

    **Arguments:**

    - `path`: the file; its extension selects the format.
    - `merge_vertices`: merge vertices with bit-identical coordinates (STL stores
      every triangle separately; OBJ files split vertices at texture seams),
      except where merging would make the mesh non-manifold (sheets that touch at
      a point or along an edge, solids that share a face): those vertices are
      kept apart, with a warning naming them. The first occurrence keeps its
      place, so files without duplicates keep their vertex numbering.
    - `repair`: merge every position (when `merge_vertices`), then remove
      degenerate and duplicate faces, separate the faces
      of non-manifold edges and split bow-tie vertices (`jaxgeo.repair_mesh`;
      `"remove"` removes the smallest faces of non-manifold edges instead), with
      a warning saying what changed.

    Polygons (quads, …) are triangulated by trimesh. The result is validated by
    `Mesh`.

    **Raises** `JaxgeoError` naming the file and the problem when the file is
    missing, cannot be parsed, holds less than its header promises (PLY, OFF,
    binary STL) or an OBJ face index 0, holds no triangles, or fails `Mesh`
    validation.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        fail(f"mesh file not found: {path}")
    if not os.path.isfile(path):
        fail(f"mesh path is not a file: {path}")
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if not ext:
        fail(
            f"cannot tell the format of mesh file {path}: it has no extension "
            "(expected .obj, .ply, .stl, .off, …)"
        )
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise JaxgeoError(f"could not read mesh file {path}: {e}") from e
    if not data.strip():
        fail(f"mesh file {path} is empty")
    if ext == "obj":
        data = _obj_text(_utf8(data), path)
    elif ext == "off":
        data = _utf8(data)
        _check_off_counts(data, path)
    elif ext == "ply":
        _check_ply_counts(data, path)
    elif ext == "stl":
        data = _stl_bytes(data, path)
    trimesh_log = logging.getLogger("trimesh")
    level = trimesh_log.level
    try:
        # trimesh logs (and then swallows or re-raises) parse failures; the
        # JaxgeoError below says the same once.
        trimesh_log.setLevel(logging.CRITICAL)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy warnings on garbage numbers
            loaded = trimesh.load(
                io.BytesIO(data), file_type=ext, force="mesh", process=False
            )
        if not isinstance(loaded, trimesh.Trimesh):
            fail(f"mesh file {path} holds no triangle mesh")
        vertices = np.asarray(loaded.vertices)
        faces = np.asarray(loaded.faces)
    except JaxgeoError:
        raise
    except Exception as e:  # trimesh raises many types on malformed files
        raise JaxgeoError(
            f"could not read mesh file {path} as {ext.upper()}: {type(e).__name__}: {e}"
        ) from e
    finally:
        trimesh_log.setLevel(level)
    if faces.size == 0:
        fail(f"mesh file {path} holds no triangles")
    if merge_vertices and vertices.ndim == 2 and faces.dtype.kind in "iu":
        # repair separates what a plain merge joins wrongly, and more (walls)
        vertices, faces, apart = merge_coincident(vertices, faces, safe=not repair)
        if apart:
            _warn_kept_apart(path, apart)
    try:
        if repair:
            how = "split" if repair is True else repair
            vertices, faces, report = repair_mesh(
                vertices, faces, nonmanifold=how, warn=False
            )
            if report.changed:
                warnings.warn(
                    f"repaired {path}: {report}", stacklevel=caller_stacklevel()
                )
        return Mesh(vertices, faces)
    except JaxgeoError as e:
        raise JaxgeoError(f"invalid mesh in {path}: {e}") from e


#: An OBJ face token whose vertex index is 0 (indices start at 1; −1 is the last).
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f [^\r\n#]*?(?<= )[-+]?0+(?=[ /\r\n#]|$)")


def _obj_text(data: bytes, path: str) -> bytes:
    """An OBJ as trimesh reads it: tabs are spaces and lines lose their leading
    blanks (trimesh reads `v\\t1\\t2\\t3` as nothing); a face index 0 refuses."""
    data = re.sub(rb"(?m)^[ ]+", b"", data.replace(b"\t", b" "))
    bad = _OBJ_ZERO_INDEX.search(data)
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        end = data.find(b"\n", bad.start())
        text = data[bad.start() : None if end < 0 else end]
        text = text.decode("utf-8", "replace").strip()
        n = len(_OBJ_ZERO_INDEX.findall(data))
        fail(
            f"OBJ file {path} has a face with vertex index 0 on line {line} "
            f"({text!r}; {n} such face(s) in all): OBJ indices start at 1 "
            "(negative ones count back from the last vertex), so the file is "
            "corrupt or was written 0-based"
        )
    return data


def _data_lines(text: bytes) -> list[bytes]:
    """The non-empty lines of `text`, comments (`#` …) removed."""
    lines = (line.split(b"#", 1)[0].strip() for line in text.splitlines())
    return [line for line in lines if line]


def _short_of(path: str, fmt: str, counts: dict[str, int], held: int, unit: str):
    """Refuse a file whose header promises more elements than it holds `held`
    lines (or bytes) for."""
    promised = ", ".join(f"{n} {name}" for name, n in counts.items())
    fail(
        f"{fmt} file {path} is truncated or its header lies: the header promises "
        f"{promised}, but the file holds {held} {unit} of data after it"
    )


def _check_off_counts(data: bytes, path: str) -> None:
    """An ASCII OFF must hold the vertex and face lines its count line promises
    (trimesh reads a short file's face lines as vertices, or fewer faces)."""
    head = re.search(rb"(?:C|N|ST)?OFF", data)
    if head is None:
        return  # not an OFF: trimesh says so
    lines = _data_lines(data[head.end() :])
    if not lines:
        return
    try:
        nv, nf = (int(x) for x in lines[0].split()[:2])
    except ValueError:
        return  # a malformed count line: trimesh says so
    held = len(lines) - 1
    if held < nv:
        _short_of(path, "OFF", {"vertices": nv}, held, "lines")
    if held < nv + nf:
        _short_of(path, "OFF", {"vertices": nv, "faces": nf}, held, "lines")


#: Bytes of the PLY scalar types.
_PLY_SIZES = {
    **dict.fromkeys([b"char", b"uchar", b"int8", b"uint8"], 1),
    **dict.fromkeys([b"short", b"ushort", b"int16", b"uint16"], 2),
    **dict.fromkeys([b"int", b"uint", b"float", b"int32", b"uint32", b"float32"], 4),
    **dict.fromkeys([b"double", b"float64"], 8),
}


def _check_ply_counts(data: bytes, path: str) -> None:
    """A PLY must hold the elements its header promises: one line each in ASCII;
    in binary at least their bytes (a list of face indices: 3 or more each)."""
    end = re.search(rb"end_header[^\n]*\n", data[:65536])
    if not data.startswith(b"ply") or end is None:
        return  # not a PLY: trimesh says so
    header = _data_lines(data[: end.start()].replace(b"comment", b"#"))
    fmt = next((line.split() for line in header if line.startswith(b"format")), [])
    elements: list[list] = []  # [name, count, bytes per row at least]
    for line in header:
        words = line.split()
        if words[0] == b"element" and len(words) == 3 and words[2].isdigit():
            elements.append([words[1].decode("ascii", "replace"), int(words[2]), 0])
        elif words[0] == b"property" and elements:
            if len(words) >= 5 and words[1] == b"list":
                count, item = _PLY_SIZES.get(words[2]), _PLY_SIZES.get(words[3])
                if count is None or item is None:
                    return  # an unknown type: trimesh says so
                indices = words[4] in (b"vertex_indices", b"vertex_index")
                elements[-1][2] += count + (3 * item if indices else 0)
            elif len(words) >= 3 and words[1] in _PLY_SIZES:
                elements[-1][2] += _PLY_SIZES[words[1]]
            else:
                return
    if not elements:
        return
    counts = {name: n for name, n, _ in elements}
    least = sum(n * size for _, n, size in elements)
    body = data[end.end() :]
    if len(fmt) >= 2 and fmt[1] == b"ascii":
        held = len(_data_lines(body))
        if held < sum(counts.values()):
            _short_of(path, "PLY", counts, held, "lines")
    elif len(body) < least:
        _short_of(path, "PLY", counts, len(body), "bytes")


def _utf8(data: bytes) -> bytes:
    """Text formats as valid UTF-8: undecodable bytes (a Latin-1 comment, binary
    garbage) become U+FFFD, so trimesh never needs to guess the encoding."""
    return data.decode("utf-8", errors="replace").encode("utf-8")


def _stl_bytes(data: bytes, path: str) -> bytes:
    """Check a binary STL's triangle count against its length (84-byte header,
    then 50 bytes per triangle). Two mismatches are harmless and read with a
    warning: a count of 0 over whole triangles (some exporters never fill it in)
    and bytes after the counted triangles; a count the file does not hold is
    refused (the file is truncated, or the count is garbage)."""
    n = len(data)
    count = int.from_bytes(data[80:84], "little") if n >= 84 else -1
    if count >= 0 and n == 84 + 50 * count:
        return data  # a consistent binary STL
    if data.lstrip()[:5].lower() == b"solid":
        return _utf8(data)  # ASCII STL
    if n < 84:
        fail(
            f"mesh file {path} is neither an ASCII STL (no 'solid' keyword) nor a "
            f"binary STL (only {n} bytes, a binary STL header takes 84)"
        )
    if n > 84 + 50 * count > 84:
        warnings.warn(
            f"binary STL {path}: ignoring {n - 84 - 50 * count} bytes after its "
            f"{count} triangles",
            stacklevel=caller_stacklevel(),
        )
        return data[: 84 + 50 * count]
    held, rest = divmod(n - 84, 50)
    if count == 0 and held > 0 and rest == 0:
        warnings.warn(
            f"binary STL {path}: the header says 0 triangles but the file "
            f"holds {held}; reading {held}",
            stacklevel=caller_stacklevel(),
        )
        return data[:80] + held.to_bytes(4, "little") + data[84:]
    fail(
        f"binary STL {path} is truncated or corrupt: its header says {count} "
        f"triangles ({84 + 50 * count} bytes) but the file has {n} bytes"
        + (f" ({held} whole triangles)" if rest == 0 else "")
    )
    raise AssertionError  # unreachable: fail raises


def _warn_kept_apart(path: str, apart: list[np.ndarray]) -> None:
    shown = ", ".join("(" + ", ".join(str(int(i)) for i in g) + ")" for g in apart[:10])
    more = f", … ({len(apart)} in all)" if len(apart) > 10 else ""
    warnings.warn(
        f"{path}: {len(apart)} positions hold several vertices that were kept "
        "apart, since merging them would make the mesh non-manifold (sheets that "
        f"touch at a point or an edge, solids that share a face): vertices {shown}"
        f"{more}. A 3-D endpoint there is ambiguous: pass a jaxgeo.SurfacePoint "
        "on the intended side",
        stacklevel=caller_stacklevel(),
    )
