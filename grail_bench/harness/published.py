"""The published format of results: text files others can read, diff, check and submit to.

A published folder holds

* ``format.json``: ``{"format": "grail-bench results", "version": 1}``;
* the shared tables, one JSON object a line, ``{"hash": ..., "json": ...}`` (the exact JSON text and the hex
  SHA-256 of its UTF-8 bytes, :func:`grail_bench.harness.schema.ref`): ``configs.jsonl`` (recognizer
  configurations), ``versions.jsonl`` (package versions), ``provenance.jsonl`` and ``sources.jsonl`` (the
  submissions merged rows came from; :data:`SHARED_FILES`);
* the rows, one file per domain and kind (``minigrid/offline.jsonl``, ``minigrid/online.jsonl``,
  ``minigrid/open_set.jsonl``, ``minigrid/zero_shot.jsonl``, ``minigrid/fits.jsonl``, and the rows' per-instance
  outputs ``minigrid/outputs.jsonl`` (offline), ``online_outputs.jsonl``, ``open_set_outputs.jsonl`` and
  ``zero_shot_outputs.jsonl``; :data:`KINDS`): one row a line, its fields as the store holds them, the shared JSON
  referenced by hash (``config_ref``, ...), an output row's arrays as JSON lists (:mod:`grail_bench.harness.outputs`).

Every file is sorted (rows by their key, shared entries by hash) and written with sorted keys and no spaces, so
the same store gives byte-identical files and a republish that adds rows adds only their lines. A file larger
than :data:`GZIP_ABOVE` is gzip-compressed (``.jsonl.gz``, no name and mtime 0 in its header, so it is
deterministic too). Each line follows the JSON Schema shipped with the package (:func:`schema`, the definition
named by the file's kind).
"""

from __future__ import annotations

import gzip
import io
import json
import re
from dataclasses import MISSING, asdict, dataclass, field, fields
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any, Iterable, Iterator

from grail_bench.core.atomic import write_files
from grail_bench.core.errors import UserError
from grail_bench.harness import diagnostics
from grail_bench.harness.diagnostics import FitRow
from grail_bench.harness.modes import MODES, OnlineRow, OpenSetRow, ResultRow, ZeroShotRow
from grail_bench.harness.outputs import KINDS as OUTPUT_KINDS
from grail_bench.harness.outputs import ROW_TYPES as OUTPUT_ROWS
from grail_bench.harness.outputs import OutputRow, arrays_of, pack_arrays
from grail_bench.harness.schema import SHARED, ref
from grail_bench.harness.store import ResultsStore

FORMAT = {"format": "grail-bench results", "version": 1}
#: Row kind (a file's stem) -> its row type.
KINDS: dict[str, type] = {"offline": ResultRow, "online": OnlineRow, "open_set": OpenSetRow,
                          "zero_shot": ZeroShotRow, "fits": FitRow} | {k.name: k.row for k in OUTPUT_KINDS.values()}
#: Row kind -> the fields that identify a row (its sort key).
KEYS = {kind: next(m.key for m in MODES.values() if m.row is row_type) for kind, row_type in KINDS.items()
        if row_type not in (FitRow, *OUTPUT_ROWS)} | {"fits": diagnostics.KEY} | {
            k.name: k.key for k in OUTPUT_KINDS.values()}
#: Shared field -> the file holding its JSON texts once.
SHARED_FILES = {name: f"{table}.jsonl" for name, table in SHARED.items()}
#: Files larger than this (bytes, uncompressed) are written gzip-compressed.
GZIP_ABOVE = 1 << 20
#: The most a row file may hold, uncompressed (the published store's largest holds 34 MiB): a compressed
#: file that unpacks to more is refused before it fills memory.
MAX_FILE_BYTES = 1 << 30
SCHEMA_FILE = "results.schema.json"
_HASH = {"type": "string", "pattern": "^[0-9a-f]{64}$"}
_TYPES = {"str": "string", "int": "integer", "float": "number", "bool": "boolean"}
#: An output row's array -> its schema.
_ARRAY_SPECS = {
    "y_true": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    "lengths": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    "held_out": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    "scores": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
    "calibration": {"type": "array", "items": {"type": "number"}},
}


class PublishedError(UserError):
    """A published folder or file cannot be read, or breaks the format."""


@dataclass
class Published:
    """What a published folder holds: rows by kind and domain file, and the shared JSON texts by hash.

    Attributes:
        root: The folder (the one holding ``format.json``).
        rows: Row kind -> rows read, of that kind's row type, with their shared JSON in place.
        files: Row kind -> the files its rows came from.
        shared: Shared field -> {hash: JSON text}.
    """

    root: Path
    rows: dict[str, list[Any]] = field(default_factory=dict)
    files: dict[str, list[Path]] = field(default_factory=dict)
    shared: dict[str, dict[str, str]] = field(default_factory=dict)

    def all_rows(self) -> list[Any]:
        """Every row, of every kind."""
        return [r for rows in self.rows.values() for r in rows]


# --- the schema --------------------------------------------------------------------------------------------------


def build_schema() -> dict[str, Any]:
    """The JSON Schema of the format, made from the row types (the shipped file is this, see :func:`schema`)."""
    defs: dict[str, Any] = {
        "format": {"type": "object", "required": ["format", "version"], "additionalProperties": False,
                   "properties": {"format": {"const": FORMAT["format"]}, "version": {"const": FORMAT["version"]}}},
        "shared": {"type": "object", "required": ["hash", "json"], "additionalProperties": False,
                   "description": "A JSON text shared by many rows, keyed by the hex SHA-256 of its UTF-8 bytes.",
                   "properties": {"hash": _HASH, "json": {"type": "string"}}},
    }
    for kind, row_type in KINDS.items():
        properties, required = {}, []
        for f in fields(row_type):
            if f.name == "data":  # an output row's arrays, as lists
                properties |= {name: _ARRAY_SPECS[name] for name in row_type.NAMES}
                required += list(row_type.NAMES)
                continue
            name = f"{f.name}_ref" if f.name in SHARED else f.name
            base, _, optional = str(f.type).partition(" | ")
            spec = dict(_HASH) if f.name in SHARED else {"type": _TYPES[base]}
            if optional:
                spec["type"] = [spec["type"], "null"]
            properties[name] = spec
            if f.default is MISSING:
                required.append(name)
        defs[kind] = {"type": "object", "required": required, "additionalProperties": False,
                      "description": f"One row of a <domain>/{kind}.jsonl file ({row_type.__name__}).",
                      "properties": properties}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "urn:grail-bench:results:1",
            "title": "grail-bench published results",
            "description": "Each line of a published file is one object of the definition its file names: "
                           "format.json is `format`; configs.jsonl, versions.jsonl, provenance.jsonl and "
                           "sources.jsonl are `shared`; <domain>/<kind>.jsonl[.gz] is `<kind>`.",
            "$defs": defs}


@cache
def schema() -> dict[str, Any]:
    """The JSON Schema shipped with the package (``grail_bench/harness/results.schema.json``)."""
    return json.loads(resources.files("grail_bench.harness").joinpath(SCHEMA_FILE).read_text(encoding="utf-8"))


@cache
def _validator(definition: str) -> Any:
    import jsonschema

    whole = schema()
    return jsonschema.Draft202012Validator({**whole, "$ref": f"#/$defs/{definition}"})


#: JSON Schema type -> test of a decoded JSON value (``integer`` as JSON Schema 2020-12 has it: 1.0 is one).
_IS = {"string": lambda v: isinstance(v, str), "null": lambda v: v is None,
       "boolean": lambda v: isinstance(v, bool),
       "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
       "integer": lambda v: (isinstance(v, int) and not isinstance(v, bool))
       or (isinstance(v, float) and v.is_integer())}


@cache
def _quick(definition: str) -> Any:
    """A fast test of the lines of a flat definition (objects of typed scalar properties: every row kind's but
    the outputs), true exactly when the schema's validator passes the line; None for any other definition."""
    spec = schema()["$defs"][definition]
    tests, required = {}, set(spec.get("required", ()))
    for name, prop in spec["properties"].items():
        if set(prop) - {"type", "pattern"}:
            return None
        kinds = prop["type"] if isinstance(prop["type"], list) else [prop["type"]]
        pattern = re.compile(prop["pattern"]) if "pattern" in prop else None
        tests[name] = (tuple(_IS[k] for k in kinds), pattern)

    def ok(value: Any) -> bool:
        if not isinstance(value, dict) or not required <= value.keys() or not value.keys() <= tests.keys():
            return False
        for name, v in value.items():
            kinds, pattern = tests[name]
            if not any(is_kind(v) for is_kind in kinds):
                return False
            if pattern is not None and isinstance(v, str) and not pattern.search(v):
                return False
        return True

    return ok if spec.get("additionalProperties") is False else None


def check_line(definition: str, value: Any, where: str) -> None:
    """Check one line against its definition of the schema (:func:`_quick` where it applies, else and for the
    message the schema's validator).

    Raises:
        PublishedError: Naming the line and the first error.
    """
    quick = _quick(definition)
    if quick is not None and quick(value):
        return
    error = next(iter(_validator(definition).iter_errors(value)), None)
    if error is not None:
        path = ".".join(str(p) for p in error.absolute_path)
        raise PublishedError(f"{where}: {path + ': ' if path else ''}{error.message}")


# --- writing -----------------------------------------------------------------------------------------------------


def dumps(value: Any) -> str:
    """One line of the format: sorted keys, no spaces, no NaN."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def line_of(row: Any) -> dict[str, Any]:
    """A row as a line of its file: its fields, the shared JSON replaced by its hash."""
    if isinstance(row, OUTPUT_ROWS):
        out = {k: v for k, v in asdict(row).items() if k != "data"}
        if isinstance(row, OutputRow):
            out["posterior"] = bool(row.posterior)
        return out | {name: array.tolist() for name, array in row.named().items()}
    out = asdict(row)
    for name in SHARED:
        if name in out:
            out[f"{name}_ref"] = ref(out.pop(name))
    return out


def row_key(kind: str, line: dict[str, Any]) -> tuple:
    """A line's sort key: the row's key (the store's primary key, unique in a file)."""
    return tuple(line[k] for k in KEYS[kind])


@cache
def _domains() -> dict[str, str]:
    from grail_bench.task.registration import shipped_tasks

    return {task_id: task.domain for task_id, task in shipped_tasks().items()}


def domain_of(task_id: str) -> str:
    """The domain folder of a task's rows (``other`` for a task grail-bench does not ship)."""
    return _domains().get(task_id, "other")


def render(rows_by_kind: dict[str, Iterable[Any]], shared_texts: bool = True) -> dict[str, str]:
    """The published files of rows, as text: relative path (without ``.gz``) -> content.

    Args:
        rows_by_kind: Row kind -> rows.
        shared_texts: Also the shared tables of the texts the rows reference.
    """
    files: dict[str, list[tuple[tuple, str]]] = {}
    shared: dict[str, dict[str, str]] = {name: {} for name in SHARED}
    for kind, rows in rows_by_kind.items():
        for row in rows:
            plain = {} if isinstance(row, OUTPUT_ROWS) else asdict(row)
            for name in SHARED:
                if plain.get(name) is not None:
                    shared[name][ref(plain[name])] = plain[name]
            line = line_of(row)
            try:
                text = dumps(line)
            except ValueError as exc:
                raise PublishedError(f"cannot publish a {kind} row of {row.task}: {exc}") from None
            files.setdefault(f"{domain_of(row.task)}/{kind}.jsonl", []).append((row_key(kind, line), text))
    out = {"format.json": dumps(FORMAT) + "\n"}
    for path, lines in files.items():
        out[path] = "".join(text + "\n" for _, text in sorted(lines))
    if shared_texts:
        for name, texts in shared.items():
            if texts:
                out[SHARED_FILES[name]] = "".join(dumps({"hash": h, "json": texts[h]}) + "\n" for h in sorted(texts))
    return out


def _gzip(text: str) -> bytes:
    buffer = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buffer, mtime=0, compresslevel=9) as handle:
        handle.write(text.encode())
    return buffer.getvalue()


def write(files: dict[str, str], out: Path) -> list[Path]:
    """Write rendered files (:func:`render`) into ``out``, compressing the large ones; a published file there that
    is not among them (or is now compressed otherwise) is removed, so ``out`` holds exactly these.

    Returns:
        The files written, sorted.
    """
    written, changed = [], {}
    for rel, text in sorted(files.items()):
        data = text.encode()
        path = out / rel
        if rel.endswith(".jsonl") and len(data) > GZIP_ABOVE:
            path, data = out / f"{rel}.gz", _gzip(text)
        if not path.exists() or path.read_bytes() != data:
            changed[path] = data
        written.append(path)
    write_files(changed)  # all or none
    for old in [*out.glob("*.jsonl*"), *out.glob("*/*.jsonl*")]:
        if old not in written:
            old.unlink()
    return sorted(written)


def export(store: ResultsStore, out: Path) -> list[Path]:
    """Write every row of a store into ``out`` in the published format.

    Returns:
        The files written.
    """
    return write(render({kind: store.select(row_type) for kind, row_type in KINDS.items()}), out)


# --- reading -----------------------------------------------------------------------------------------------------


def find_root(path: Path) -> Path:
    """The published folder of ``path`` (a folder, or a file inside one): the nearest holding ``format.json``.

    Raises:
        PublishedError: If there is none.
    """
    path = path.expanduser()
    if not path.exists():
        raise PublishedError(f"no such file or folder: {path}")
    for folder in ([path] if path.is_dir() else []) + list(path.parents):
        if (folder / "format.json").is_file():
            return folder
    raise PublishedError(f"{path} is not in a folder of published results (no format.json beside it or above)")


def read_lines(path: Path) -> Iterator[tuple[int, Any]]:
    """``(line number, value)`` of a ``.jsonl`` or ``.jsonl.gz`` file.

    Raises:
        PublishedError: For a line that is not JSON, or a file that cannot be read.
    """
    try:
        with (gzip.open(path, "rb") if path.name.endswith(".gz") else path.open("rb")) as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            raise PublishedError(f"{path}: more than {MAX_FILE_BYTES >> 20} MiB of rows in one file; split it by "
                                 "domain and kind")
        text = raw.decode()
    except (OSError, EOFError, gzip.BadGzipFile, UnicodeDecodeError) as exc:
        raise PublishedError(f"cannot read {path}: {exc}") from None
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            yield number, json.loads(line)
        except json.JSONDecodeError as exc:
            raise PublishedError(f"{path}:{number}: not JSON ({exc.msg})") from None


def kind_of(path: Path) -> str | None:
    """The row kind a file holds, from its name (None for a file that holds no rows)."""
    stem = path.name.removesuffix(".gz").removesuffix(".jsonl")
    return stem if stem in KINDS and path.parent.name and path.name.endswith((".jsonl", ".jsonl.gz")) else None


def read(path: Path, check: bool = True) -> Published:
    """Read a published folder, or one row file inside one (with the folder's shared tables).

    Args:
        path: The folder or file.
        check: Check every line against the schema.

    Raises:
        PublishedError: For a file that breaks the format (naming file, line and error), or a row referencing a
            shared text its folder does not hold.
    """
    root = find_root(path)
    fmt = json.loads((root / "format.json").read_text(encoding="utf-8"))
    if fmt != FORMAT:
        raise PublishedError(f"{root / 'format.json'}: not {FORMAT['format']} version {FORMAT['version']}: {fmt}")
    out = Published(root=root)
    for name, file in SHARED_FILES.items():
        texts: dict[str, str] = {}
        for candidate in (root / file, root / f"{file}.gz"):
            if candidate.exists():
                for number, value in read_lines(candidate):
                    if check:
                        check_line("shared", value, f"{candidate}:{number}")
                    if ref(value["json"]) != value["hash"]:
                        raise PublishedError(f"{candidate}:{number}: hash is not the SHA-256 of its json")
                    texts[value["hash"]] = value["json"]
        out.shared[name] = texts
    path = path.expanduser()
    files = [path] if path.is_file() else sorted(p for p in root.glob("*/*.jsonl*") if kind_of(p))
    for file in files:
        kind = kind_of(file)
        if kind is None:
            raise PublishedError(f"{file} holds no rows: a row file is <domain>/<kind>.jsonl[.gz], kind one of "
                                 f"{', '.join(KINDS)}")
        out.files.setdefault(kind, []).append(file)
        rows = out.rows.setdefault(kind, [])
        for number, value in read_lines(file):
            if check:
                check_line(kind, value, f"{file}:{number}")
            rows.append(_row(kind, value, out.shared, f"{file}:{number}"))
    return out


def _row(kind: str, line: dict[str, Any], shared: dict[str, dict[str, str]], where: str) -> Any:
    values = dict(line)
    if kind in OUTPUT_KINDS:
        output = OUTPUT_KINDS[kind]
        try:
            arrays = arrays_of(output.row.NAMES, {name: values.pop(name, None) for name in output.row.NAMES})
        except ValueError as exc:
            raise PublishedError(f"{where}: {exc}") from None
        if not output.consistent(arrays):
            raise PublishedError(f"{where}: {output.shapes}")
        values["data"] = pack_arrays(output.row.NAMES, arrays)
    for name in SHARED:
        key = f"{name}_ref"
        if key in values:
            h = values.pop(key)
            if h is not None and h not in shared[name]:
                raise PublishedError(f"{where}: {key} {h[:12]}... is not in {SHARED_FILES[name]}")
            values[name] = None if h is None else shared[name][h]
    try:
        return KINDS[kind](**values)
    except TypeError as exc:
        raise PublishedError(f"{where}: not a {kind} row ({exc})") from None


def load(path: Path, store: ResultsStore, check: bool = True) -> int:
    """Add the rows of a published folder (or file) to a store.

    Returns:
        How many rows were new.
    """
    return store.add(read(path, check=check).all_rows())
