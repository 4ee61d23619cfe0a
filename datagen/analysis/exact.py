"""Exact statistics of more values than a process should hold: the numbers ``np.mean``,
``np.median``, ``np.percentile`` and ``np.histogram`` give on the whole array, bit for bit,
computed from values spilled to disk (:class:`Spill`) and read back in bounded pieces.

- **Means** follow numpy's own summation: pairwise, over blocks of at most
  :data:`PAIRWISE_BLOCK` values summed with 8 accumulators (``pairwise_sum`` in numpy's
  ``loops_utils.h``), split where numpy splits for the whole array's length. The tree
  depends only on the length, which is known before the values are read again, so a
  running :class:`OrderedSum` fed the values in order in any pieces gives numpy's sum.
- **Order statistics** (medians, percentiles) are found by radix selection over the
  values' sortable bit patterns (:func:`order_statistics`): 16 bits a pass, until the
  values sharing a prefix with the wanted one are few enough to sort.
- **Percentiles and medians** are then formed as numpy forms them from their order
  statistics (:func:`percentile`, :func:`median`).
"""

from __future__ import annotations

import contextlib
import math
import shutil
import tempfile
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO, Final, Self

import numpy as np
from numpy.typing import NDArray

from datagen.atomic import scratch_file

__all__ = [
    "PAIRWISE_BLOCK",
    "SELECT_GATHER",
    "OrderedSum",
    "Spill",
    "median",
    "median_positions",
    "order_statistics",
    "percentile",
    "percentile_positions",
]

#: numpy sums at most this many values with its 8-accumulator loop before it splits (PW_BLOCKSIZE).
PAIRWISE_BLOCK: Final = 128
_ADD: Final = -1  # the plan's "add the last two sums"
#: What numpy's reduction adds its tree's sum to: its identity, +0.0 (numpy 2.4: a sum of
#: negative zeros is +0.0), or -0.0 where a version keeps their sign. Asked of numpy, not assumed.
_REDUCE_START: Final = float(np.add.reduce(np.array([-0.0])))
#: Bits of a value's sortable key that one selection pass resolves.
_RADIX_BITS: Final = 16
#: Values sharing a key prefix with a wanted order statistic that are gathered and sorted
#: rather than split by a further pass.
SELECT_GATHER: Final = 1 << 20


# --- sums ------------------------------------------------------------------------------------
def _pairwise_plan(n: int) -> Iterator[int]:
    """numpy's summation tree of ``n`` values in postfix: a block length (sum the next that
    many values) or :data:`_ADD` (add the last two sums)."""
    todo = [n]  # lengths still to sum, and _ADD markers, the next on top
    while todo:
        m = todo.pop()
        if m == _ADD or m <= PAIRWISE_BLOCK:
            yield m
            continue
        half = m // 2
        half -= half % 8
        todo += [_ADD, m - half, half]


def _block_sums(blocks: NDArray[np.float64]) -> NDArray[np.float64]:
    """numpy's sum of each row of ``(m, L)`` blocks, ``L <= PAIRWISE_BLOCK``: under 8 values
    one after another from -0.0; else 8 running sums, added as a tree, then the rest."""
    m, length = blocks.shape
    if length < 8:
        out = np.full(m, -0.0)
        for i in range(length):
            out += blocks[:, i]
        return out
    r = blocks[:, :8].copy()
    end = length - length % 8
    for i in range(8, end, 8):
        r += blocks[:, i:i + 8]
    out = ((r[:, 0] + r[:, 1]) + (r[:, 2] + r[:, 3])) + ((r[:, 4] + r[:, 5]) + (r[:, 6] + r[:, 7]))
    for i in range(end, length):
        out += blocks[:, i]
    return out


class OrderedSum:
    """``np.sum`` (and ``np.mean``) of ``n`` float64 values fed in order, in pieces of any
    size; holds at most one block and the tree's open sums."""

    def __init__(self, n: int) -> None:
        self.n = n
        self._plan = _pairwise_plan(n) if n else iter(())
        self._op = next(self._plan, None)
        self._stack: list[float] = []
        self._pending = np.zeros(0)
        self._fed = 0

    def feed(self, values: NDArray[np.float64]) -> None:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        self._fed += values.size
        if self._fed > self.n:
            raise ValueError(f"fed {self._fed} values to a sum of {self.n}")
        buf = np.concatenate([self._pending, values]) if self._pending.size else values
        ops: list[tuple[int, int] | None] = []
        pos = 0
        while self._op is not None:
            if self._op == _ADD:
                ops.append(None)
            elif pos + self._op <= buf.size:
                ops.append((pos, self._op))
                pos += self._op
            else:
                break
            self._op = next(self._plan, None)
        starts: dict[int, list[int]] = defaultdict(list)
        for op in ops:
            if op is not None:
                starts[op[1]].append(op[0])
        sums: dict[int, float] = {}
        for length, firsts in starts.items():
            index = np.asarray(firsts)[:, None] + np.arange(length)
            sums.update(zip(firsts, _block_sums(buf[index]).tolist(), strict=True))
        stack = self._stack
        for op in ops:
            if op is None:
                right = stack.pop()
                stack.append(stack.pop() + right)
            else:
                stack.append(sums[op[0]])
        self._pending = buf[pos:].copy()

    def total(self) -> float:
        """The sum (0.0 of no values); every value must have been fed."""
        if self._fed != self.n:
            raise ValueError(f"a sum of {self.n} values was fed {self._fed}")
        return self._stack[0] + _REDUCE_START if self.n else 0.0

    def mean(self) -> float:
        return self.total() / self.n


# --- order statistics ------------------------------------------------------------------------
def _keys(values: NDArray[np.float64]) -> NDArray[np.uint64]:
    """Unsigned keys that sort as the (non-NaN) float64 ``values`` do."""
    bits = np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)
    return np.where(bits >> np.uint64(63), ~bits, bits | np.uint64(1 << 63))


Chunks = Callable[[], Iterator[tuple[NDArray[np.int64], NDArray[np.float64]]]]


def order_statistics(chunks: Chunks, wanted: dict[int, set[int]], *, gather: int | None = None
                     ) -> dict[tuple[int, int], float]:
    """The ``k``-th smallest value (0-based) of group ``g`` for each ``k`` in ``wanted[g]``.

    ``chunks()`` yields ``(group, values)`` pieces of every group's values, in any order,
    and is called once per pass (usually two); NaNs are not counted (a group holding one has
    no order statistics: numpy's median and percentile are NaN). Memory: one piece, a
    2**16-bin histogram per group, and about ``gather`` (:data:`SELECT_GATHER`) values per
    wanted one, gathered and sorted once fewer than that share its key's prefix."""
    gather = SELECT_GATHER if gather is None else gather
    groups = np.array(sorted(wanted), dtype=np.int64)
    if len(groups) >= 1 << (64 - 3 * _RADIX_BITS):
        raise ValueError(f"{len(groups)} groups: at most {1 << (64 - 3 * _RADIX_BITS)} at once")
    bins = 1 << _RADIX_BITS
    # per wanted (group slot, k): the key prefix it lies under, the prefix's bits, its rank among them
    state = {(i, k): (0, 0, k) for i, g in enumerate(groups.tolist()) for k in wanted[g]}
    under: dict[tuple[int, int], int] = {}  # values under that prefix

    def pieces() -> Iterator[tuple[NDArray[np.uint64], NDArray[np.uint64], NDArray[np.float64]]]:
        """(group slot, key, value) of each non-NaN value of a wanted group."""
        for group, values in chunks():
            keep = np.isin(group, groups) & ~np.isnan(values)
            yield (np.searchsorted(groups, group[keep]).astype(np.uint64), _keys(values[keep]), values[keep])

    def matches(prefixes: dict[int, NDArray[np.uint64]], slot, keys):
        """Per prefix length: which values lie under one of ``prefixes`` (slot, prefix) codes,
        and the index of that code among the sorted ones."""
        for shift, codes in prefixes.items():
            code = (slot << np.uint64(shift)) | (keys >> np.uint64(64 - shift))
            at = np.minimum(np.searchsorted(codes, code), len(codes) - 1)
            yield shift, codes, at, codes[at] == code

    def open_codes(select) -> dict[int, NDArray[np.uint64]]:
        codes: dict[int, set[int]] = defaultdict(set)
        for (slot, k), (prefix, shift, _) in state.items():
            if select(slot, k, shift):
                codes[shift].add((slot << shift) | prefix)
        return {shift: np.array(sorted(c), dtype=np.uint64) for shift, c in codes.items()}

    def descend(hist: dict[tuple[int, int], NDArray[np.int64]]) -> None:
        for (slot, k), (prefix, shift, rank) in state.items():
            h = hist.get((shift, (slot << shift) | prefix))
            if h is None:
                continue
            cum = np.cumsum(h)
            digit = int(np.searchsorted(cum, rank, side="right"))
            if digit >= bins:
                raise ValueError(f"group {groups[slot]} has no value of rank {k}")
            state[(slot, k)] = ((prefix << _RADIX_BITS) | digit, shift + _RADIX_BITS,
                                rank - (int(cum[digit - 1]) if digit else 0))
            under[(slot, k)] = int(h[digit])

    # the first pass: every group's histogram of the keys' top 16 bits at once
    total = np.zeros(len(groups) * bins, dtype=np.int64)
    for slot, keys, _ in pieces():
        top = (keys >> np.uint64(64 - _RADIX_BITS)).astype(np.int64)
        total += np.bincount(slot.astype(np.int64) * bins + top, minlength=total.size)
    descend({(0, i): total[i * bins:(i + 1) * bins] for i in range(len(groups))})
    while True:  # further passes where too many values share the prefix
        codes = open_codes(lambda slot, k, shift: under[(slot, k)] > gather and shift < 64)
        if not codes:
            break
        hists = {shift: np.zeros(len(c) * bins, dtype=np.int64) for shift, c in codes.items()}
        low = {shift: np.full(len(c), np.iinfo(np.uint64).max, dtype=np.uint64) for shift, c in codes.items()}
        high = {shift: np.zeros(len(c), dtype=np.uint64) for shift, c in codes.items()}
        for slot, keys, _ in pieces():
            for shift, _, at, hit in matches(codes, slot, keys):
                digit = ((keys[hit] >> np.uint64(64 - shift - _RADIX_BITS)) & np.uint64(bins - 1)).astype(np.int64)
                hists[shift] += np.bincount(at[hit] * bins + digit, minlength=hists[shift].size)
                np.minimum.at(low[shift], at[hit], keys[hit])
                np.maximum.at(high[shift], at[hit], keys[hit])
        # a prefix whose values are all one value (many ties, such as exact zeros) is done
        tied = {key: int(low[shift][j]) for key, (prefix, shift, _) in state.items() if shift in codes
                for j in np.flatnonzero(codes[shift] == np.uint64((key[0] << shift) | prefix))
                if low[shift][j] == high[shift][j]}
        descend({(shift, int(code)): hists[shift][j * bins:(j + 1) * bins]
                 for shift, c in codes.items() for j, code in enumerate(c.tolist())})
        for key, value_key in tied.items():
            state[key] = (value_key, 64, 0)
    # a whole key: the value itself; else the last pass gathers the values under the prefix and sorts them
    out = {key: _value(prefix) for key, (prefix, shift, _) in state.items() if shift >= 64}
    codes = open_codes(lambda slot, k, shift: shift < 64)
    found: dict[int, list[tuple[NDArray[np.int64], NDArray[np.float64]]]] = defaultdict(list)
    for slot, keys, values in pieces() if codes else ():
        for shift, _, at, hit in matches(codes, slot, keys):
            found[shift].append((at[hit], values[hit]))
    pools: dict[tuple[int, int], NDArray[np.float64]] = {}
    for shift, c in codes.items():
        at = np.concatenate([a for a, _ in found[shift]])
        values = np.concatenate([v for _, v in found[shift]])
        order = np.argsort(at, kind="stable")
        for j, piece in enumerate(np.split(values[order], np.searchsorted(at[order], np.arange(1, len(c))))):
            pools[(shift, int(c[j]))] = piece
    for key, (prefix, shift, rank) in state.items():
        if key not in out:
            pool = pools[(shift, (key[0] << shift) | prefix)]
            out[key] = float(pool[np.argsort(_keys(pool), kind="stable")][rank])
    return {(int(groups[slot]), k): v for (slot, k), v in out.items()}


def _value(key: int) -> float:
    """The float64 whose :func:`_keys` key is ``key``."""
    bits = key & ~(1 << 63) if key >> 63 else ~key & ((1 << 64) - 1)
    return float(np.array([bits], dtype=np.uint64).view(np.float64)[0])


def median_positions(n: int) -> tuple[int, ...]:
    """The order statistics ``np.median`` of ``n`` values takes."""
    return ((n - 1) // 2,) if n % 2 else (n // 2 - 1, n // 2)


def median(n: int, stat: Callable[[int], float]) -> float:
    """``np.median`` of ``n`` values from their order statistics ``stat(k)``."""
    positions = median_positions(n)
    if len(positions) == 1:
        return float(stat(positions[0]))
    return (stat(positions[0]) + stat(positions[1])) / 2


def _virtual_index(n: int, q: float) -> tuple[float, int, int]:
    virtual = (n - 1) * (q / 100)
    if virtual >= n - 1:
        return virtual, n - 1, -1  # numpy takes the last value twice, its gamma from index -1
    below = math.floor(virtual)
    return virtual, below, below


def percentile_positions(n: int, q: float) -> tuple[int, int]:
    """The order statistics ``np.percentile(values, q)`` (linear) of ``n`` values takes."""
    _, below, _ = _virtual_index(n, q)
    return below, min(below + 1, n - 1)


def percentile(n: int, q: float, stat: Callable[[int], float]) -> float:
    """``np.percentile(values, q)`` (method ``linear``) of ``n`` values from their order
    statistics ``stat(k)``, with numpy's interpolation arithmetic."""
    virtual, _, origin = _virtual_index(n, q)
    below, above = percentile_positions(n, q)
    a, b = stat(below), stat(above)
    gamma = virtual - origin
    diff = b - a
    return b - diff * (1 - gamma) if gamma >= 0.5 else a + diff * gamma


# --- spilled columns -------------------------------------------------------------------------
class Spill:
    """Columns of values kept on disk, in parts (one per shard), each part's rows with a
    ``rank`` (their frames' positions in the dataset's frame order), to be read back part by
    part (:meth:`parts`) or in the dataset's frame order (:meth:`ordered`). A stream is a set
    of columns of equal length; each column is one file that parts are appended to. The
    files live in a temporary folder removed by :meth:`close` (or on leaving a ``with``
    block)."""

    def __init__(self) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="datagen-spill-"))
        self._parts: dict[str, list[tuple[int, int, int, int]]] = defaultdict(list)  # (first row, rows, min, max rank)
        self.rows: dict[str, int] = defaultdict(int)
        self._kinds: dict[tuple[str, str], tuple[np.dtype, tuple[int, ...]]] = {}  # column -> dtype, row shape
        self._files: dict[tuple[str, str], BinaryIO] = {}

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for f in self._files.values():
            with contextlib.suppress(OSError):  # a full disk: the folder goes all the same
                f.close()
        self._files.clear()
        shutil.rmtree(self.folder, ignore_errors=True)

    def _file(self, stream: str, column: str) -> BinaryIO:
        key = (stream, column)
        if key not in self._files:
            self._files[key] = scratch_file(self.folder, f"{stream}.{column}.bin")
        return self._files[key]

    def _append(self, stream: str, column: str, values: NDArray) -> None:
        kind = (values.dtype, values.shape[1:])
        if self._kinds.setdefault((stream, column), kind) != kind:
            raise ValueError(f"{stream}.{column}: {kind} values after {self._kinds[(stream, column)]}")
        f = self._file(stream, column)
        try:
            f.seek(0, 2)
            f.write(np.ascontiguousarray(values).tobytes())
            f.flush()  # a full disk shows here, naming the file, not at a later read
        except OSError as exc:
            raise OSError(exc.errno, f"{exc.strerror} (values spilled while reading the dataset: "
                          "set TMPDIR to a folder with room)", f.name) from exc

    def add(self, stream: str, rank: NDArray[np.integer] | None, **columns: NDArray) -> None:
        """One part's rows of ``stream``: their ``rank`` and columns (stored ordered by rank,
        rows of equal rank kept in the order given; ``rank`` None: a stream read back only
        part by part, whose order does not matter)."""
        columns = {name: np.asarray(values) for name, values in columns.items()}
        rows = len(next(iter(columns.values())))
        for name, values in columns.items():
            if len(values) != rows or (rank is not None and len(values) != len(rank)):
                raise ValueError(f"{stream}.{name}: {len(values)} values in a part of {rows} rows")
        order: slice | NDArray[np.int64] = slice(None)
        lo, hi = 0, -1
        if rank is not None:
            rank = np.asarray(rank, dtype=np.int64)
            order = np.argsort(rank, kind="stable")
            self._append(stream, "rank", rank[order])
            if rank.size:
                lo, hi = int(rank.min()), int(rank.max())
        for name, values in columns.items():
            self._append(stream, name, values[order])
        self._parts[stream].append((self.rows[stream], rows, lo, hi))
        self.rows[stream] += rows

    def _read(self, stream: str, first: int, rows: int, columns: tuple[str, ...]) -> dict[str, NDArray]:
        out = {}
        for c in columns:
            dtype, shape = self._kinds[(stream, c)]
            width = math.prod(shape)
            f = self._file(stream, c)
            f.seek(first * width * dtype.itemsize)
            out[c] = np.fromfile(f, dtype=dtype, count=rows * width).reshape(rows, *shape)
        return out

    def parts(self, stream: str, *columns: str) -> Iterator[dict[str, NDArray]]:
        """Each part's columns, in the order the parts were added."""
        for first, rows, _, _ in self._parts[stream]:
            if rows:
                yield self._read(stream, first, rows, columns)

    def ordered(self, stream: str, *columns: str, window: int = 4096) -> Iterator[dict[str, NDArray]]:
        """The columns in frame order (rows of a frame in the order their part gave them),
        ``window`` ranks at a time: the same order as every part's rows put together and
        sorted by rank with a stable sort."""
        spans = [span for span in self._parts[stream] if span[1]]
        if not spans:
            return
        last = max(hi for *_, hi in spans)
        for start in range(0, last + 1, window):
            stop = start + window
            pieces = []
            for first, rows, lo, hi in spans:
                if hi < start or lo >= stop:
                    continue
                rank = self._read(stream, first, rows, ("rank",))["rank"]
                a, b = (int(v) for v in np.searchsorted(rank, [start, stop]))
                pieces.append({"rank": rank[a:b], **self._read(stream, first + a, b - a, columns)})
            if not pieces:
                continue
            merged = {c: np.concatenate([p[c] for p in pieces]) for c in ("rank", *columns)}
            order = np.argsort(merged.pop("rank"), kind="stable")
            yield {c: v[order] for c, v in merged.items()}
