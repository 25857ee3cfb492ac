"""Sensor noise added to an 8-bit frame in one pass: random bytes, a law's tables, saturation.

A frame's noise takes its randomness from one 64-bit seed (a word of the
frame's generator): the SplitMix64 stream ``z_k = mix(seed + (k + 1) G)``
(Steele, Lea & Flood 2014; Java's ``SplittableRandom``; passes BigCrush),
whose words, read as little-endian bytes, give byte ``j`` of the frame.
Each output is a function of its index alone, so the stream is computed 64
bytes at a time.  A law is given by byte tables: the noise of a pixel is
``n = A[b] + (c >= T[b]) D[b]`` (int8) from its byte ``b`` (and, for a
two-byte law, a second byte ``c``), added with saturation as
``clip(img + n, 0, 255)``.  One byte: :class:`~cuespin.render.draw.ByteNoise`
(``T = 0``, ``D = 0``); two bytes: Walker's alias tables of
:class:`~cuespin.render.draw.AliasNoise`.

Implementations of the same arithmetic, bit for bit (so a seed gives the
same video on any CPU):

* :func:`add_noise_reference`, numpy: the definition;
* a compiled kernel (LLVM IR through llvmlite, a dependency of numba) on
  CPUs with AVX-512 VBMI: table look-ups with ``vpermi2b`` (a 128-byte
  table per instruction), 64 pixels a step, no temporaries: about 0.3 ms of
  CPU a 1280 x 720 colour frame (byte law; 0.7 ms the two-byte law) where
  the former OpenCV path (random bytes, ``cv2.LUT``, ``cv2.addWeighted``)
  took ~2.5 ms (9.5 ms the two-byte law);
* elsewhere, for a non-decreasing one-byte law (ByteNoise's) up to
  :data:`MAX_COUNT_THRESHOLDS` levels, a portable compiled kernel (any
  vector ISA LLVM targets) that counts constant thresholds instead of
  looking up: ~1.0 ms at sigma 2 and 1.7 ms at sigma 5 compiled for AVX2
  (Haswell) on this machine;
* otherwise :func:`add_noise_opencv`, 8-bit OpenCV passes over the numpy
  stream (~6 ms the byte law, ~14 ms the two-byte law; loaded machine).

Kernels compile once per process (~20-50 ms), on first use.

For a two-byte law, chunk ``i`` of 64 pixels takes its first bytes from
words ``16 i .. 16 i + 7`` and its second from ``16 i + 8 .. 16 i + 15``;
for a one-byte law, from words ``8 i .. 8 i + 7``.  A frame whose size is
not a multiple of 64 pads its last chunk (the stream is the same).
"""

from __future__ import annotations

import ctypes
import os

import numpy as np

GOLDEN = 0x9E3779B97F4A7C15
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB
CHUNK = 64          # pixels per step of the kernel (one 512-bit register of bytes)


def splitmix_words(seed: int, start: int, count: int) -> np.ndarray:
    """Words ``start .. start + count - 1`` of the SplitMix64 stream from ``seed`` (uint64)."""
    seed = int(seed) & 0xFFFFFFFFFFFFFFFF   # as the kernels read it (a negative seed too)
    z = np.arange(start + 1, start + count + 1, dtype=np.uint64)
    t = np.empty_like(z)
    with np.errstate(over="ignore"):     # in place: modular uint64 arithmetic throughout
        z *= np.uint64(GOLDEN)
        z += np.uint64(seed)
        for shift, mult in ((30, MIX1), (27, MIX2)):
            np.right_shift(z, np.uint64(shift), out=t)
            z ^= t
            z *= np.uint64(mult)
        np.right_shift(z, np.uint64(31), out=t)
        z ^= t
    return z


def noise_bytes(seed: int, n: int, two: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The first (and, ``two``, second) random byte of each of ``n`` pixels, as the kernel reads them."""
    chunks = -(-n // CHUNK)
    per = 16 if two else 8
    w = splitmix_words(seed, 0, chunks * per).reshape(chunks, per)
    first = w[:, :8].copy().view(np.uint8).ravel()[:n]
    second = w[:, 8:].copy().view(np.uint8).ravel()[:n] if two else None
    return first, second


def noise_values(tables: np.ndarray, b: np.ndarray, c: np.ndarray | None) -> np.ndarray:
    """Integer noise (int16) of bytes ``b`` (and ``c``) under a law's ``tables`` (3, 256): A, T, D."""
    A = tables[0].view(np.int8).astype(np.int16)
    n = A[b]
    if c is not None:
        n = n + (c >= tables[1][b]) * tables[2][b].astype(np.int16)
    return n


def add_noise_reference(img: np.ndarray, tables: np.ndarray, seed: int, two: bool) -> np.ndarray:
    """``clip(img + n, 0, 255)`` (uint8, img's shape), numpy: the kernel's definition."""
    b, c = noise_bytes(seed, img.size, two)
    n = noise_values(tables, b, c).reshape(img.shape)
    return np.clip(img + n, 0, 255).astype(np.uint8)


def add_noise_opencv(img: np.ndarray, tables: np.ndarray, seed: int, two: bool) -> np.ndarray:
    """:func:`add_noise_reference`'s pixels through 8-bit OpenCV passes (the
    fallback where the kernel does not run: about 3 times faster than numpy's)."""
    import cv2

    b, c = noise_bytes(seed, img.size, two)
    b = b.reshape(-1, 1)
    A = tables[0].view(np.int8).astype(np.int16)
    if c is None:
        # n = P - Q with P, Q >= 0 and one of them 0: two saturating 8-bit steps.
        P = np.maximum(A, 0).astype(np.uint8).reshape(256, 1)
        Q = np.maximum(-A, 0).astype(np.uint8).reshape(256, 1)
        flat = np.ascontiguousarray(img).reshape(-1, 1)
        out = cv2.subtract(cv2.add(flat, cv2.LUT(b, P)), cv2.LUT(b, Q))
        return out.reshape(img.shape)
    # n + 128 in uint8, then one exact integer add (as AliasNoise drew it with OpenCV).
    a = (A + 128).astype(np.uint8).reshape(256, 1)
    above = cv2.compare(c.reshape(-1, 1), cv2.LUT(b, tables[1].reshape(256, 1)), cv2.CMP_GE)
    n8 = cv2.add(cv2.LUT(b, a), cv2.bitwise_and(above, cv2.LUT(b, tables[2].reshape(256, 1))))
    flat = np.ascontiguousarray(img).reshape(-1, 1)
    return cv2.addWeighted(flat, 1.0, n8, 1.0, -128.0, dtype=cv2.CV_8U).reshape(img.shape)


def _splat(v) -> str:
    return "<" + ", ".join([f"i64 {v}"] * 8) + ">"


def _s64(v: int) -> int:
    """An unsigned 64-bit constant as LLVM's signed literal."""
    return v - (1 << 64) if v >= 1 << 63 else v


def _words_ir(name: str, first: str) -> str:
    """IR: ``%name`` (<64 x i8>), SplitMix64 words ``first + 1 .. first + 8`` (1-based counter) as bytes."""
    lanes = "<" + ", ".join(f"i64 {j + 1}" for j in range(8)) + ">"
    return (f"  %{name}.k0 = insertelement <8 x i64> poison, i64 {first}, i64 0\n"
            f"  %{name}.k1 = shufflevector <8 x i64> %{name}.k0, <8 x i64> poison, <8 x i32> zeroinitializer\n"
            f"  %{name}.k = add <8 x i64> %{name}.k1, {lanes}\n"
            f"  %{name}.g = mul <8 x i64> %{name}.k, {_splat(_s64(GOLDEN))}\n"
            f"  %{name}.z0 = add <8 x i64> %{name}.g, %seedv\n"
            f"  %{name}.a1 = lshr <8 x i64> %{name}.z0, {_splat(30)}\n"
            f"  %{name}.a2 = xor <8 x i64> %{name}.z0, %{name}.a1\n"
            f"  %{name}.a3 = mul <8 x i64> %{name}.a2, {_splat(_s64(MIX1))}\n"
            f"  %{name}.b1 = lshr <8 x i64> %{name}.a3, {_splat(27)}\n"
            f"  %{name}.b2 = xor <8 x i64> %{name}.a3, %{name}.b1\n"
            f"  %{name}.b3 = mul <8 x i64> %{name}.b2, {_splat(_s64(MIX2))}\n"
            f"  %{name}.c1 = lshr <8 x i64> %{name}.b3, {_splat(31)}\n"
            f"  %{name}.z = xor <8 x i64> %{name}.b3, %{name}.c1\n"
            f"  %{name} = bitcast <8 x i64> %{name}.z to <64 x i8>\n")


def _function_ir(loads: str, body: str, declare: str = "") -> str:
    """IR of ``void add_noise(ptr img, ptr out, i64 chunks, ptr tables, i64 seed)``:
    per chunk of 64 pixels, ``body`` leaves their noise in ``%pos`` and ``%neg``
    (its positive and negative parts), added with saturation."""
    return f"""
{declare}
declare <64 x i8> @llvm.uadd.sat.v64i8(<64 x i8>, <64 x i8>)
declare <64 x i8> @llvm.usub.sat.v64i8(<64 x i8>, <64 x i8>)

define void @add_noise(ptr noalias %img, ptr noalias %out, i64 %chunks, ptr noalias %tab, i64 %seed) {{
entry:
{loads}  %seed0 = insertelement <8 x i64> poison, i64 %seed, i64 0
  %seedv = shufflevector <8 x i64> %seed0, <8 x i64> poison, <8 x i32> zeroinitializer
  %none = icmp eq i64 %chunks, 0
  br i1 %none, label %exit, label %loop
loop:
  %i = phi i64 [0, %entry], [%inext, %loop]
{body}  %off = mul i64 %i, 64
  %gp = getelementptr i8, ptr %img, i64 %off
  %g = load <64 x i8>, ptr %gp, align 1
  %s1 = call <64 x i8> @llvm.uadd.sat.v64i8(<64 x i8> %g, <64 x i8> %pos)
  %s2 = call <64 x i8> @llvm.usub.sat.v64i8(<64 x i8> %s1, <64 x i8> %neg)
  %op = getelementptr i8, ptr %out, i64 %off
  store <64 x i8> %s2, ptr %op, align 1
  %inext = add i64 %i, 1
  %done = icmp eq i64 %inext, %chunks
  br i1 %done, label %exit, label %loop
exit:
  ret void
}}
"""


def _kernel_ir(two: bool) -> str:
    """The AVX-512 VBMI kernel: any law's tables, looked up with ``vpermi2b``."""
    per = 16 if two else 8

    def lookup(name, t, idx, neg):
        return (f"  %{name}.l = call <64 x i8> @llvm.x86.avx512.vpermi2var.qi.512("
                f"<64 x i8> %{t}0, <64 x i8> {idx}, <64 x i8> %{t}1)\n"
                f"  %{name}.h = call <64 x i8> @llvm.x86.avx512.vpermi2var.qi.512("
                f"<64 x i8> %{t}2, <64 x i8> {idx}, <64 x i8> %{t}3)\n"
                f"  %{name} = select <64 x i1> {neg}, <64 x i8> %{name}.h, <64 x i8> %{name}.l\n")

    loads = ""
    for ti, t in enumerate(("A", "T", "D") if two else ("A",)):
        for q in range(4):
            loads += (f"  %{t}{q}.p = getelementptr i8, ptr %tab, i64 {256 * ti + 64 * q}\n"
                      f"  %{t}{q} = load <64 x i8>, ptr %{t}{q}.p, align 1\n")
    body = f"  %w0 = mul i64 %i, {per}\n" + _words_ir("b", "%w0")
    body += "  %bneg = icmp slt <64 x i8> %b, zeroinitializer\n" + lookup("a", "A", "%b", "%bneg")
    if two:
        body += "  %w1 = add i64 %w0, 8\n" + _words_ir("c", "%w1")
        body += lookup("t", "T", "%b", "%bneg") + lookup("d", "D", "%b", "%bneg")
        body += ("  %up = icmp uge <64 x i8> %c, %t\n"
                 "  %dd = select <64 x i1> %up, <64 x i8> %d, <64 x i8> zeroinitializer\n"
                 "  %n = add <64 x i8> %a, %dd\n")
    else:
        body += "  %n = add <64 x i8> %a, zeroinitializer\n"
    body += ("  %pos = call <64 x i8> @llvm.smax.v64i8(<64 x i8> %n, <64 x i8> zeroinitializer)\n"
             "  %negn = sub <64 x i8> zeroinitializer, %n\n"
             "  %neg = call <64 x i8> @llvm.smax.v64i8(<64 x i8> %negn, <64 x i8> zeroinitializer)\n")
    declare = ("declare <64 x i8> @llvm.x86.avx512.vpermi2var.qi.512(<64 x i8>, <64 x i8>, <64 x i8>)\n"
               "declare <64 x i8> @llvm.smax.v64i8(<64 x i8>, <64 x i8>)")
    return _function_ir(loads, body, declare)


def count_thresholds(table: np.ndarray):
    """A non-decreasing one-byte law ``table`` (256 ints) as counts: ``max(table[b], 0)``
    is the number of ``up`` thresholds ``<= b``, ``max(-table[b], 0)`` the number
    of ``down`` thresholds ``> b``; None if the table decreases anywhere."""
    t = np.asarray(table, dtype=int)
    if np.any(np.diff(t) < 0):
        return None
    up = [int(np.argmax(t >= level)) for level in range(1, max(int(t.max()), 0) + 1)]
    if int(t.min()) < 0 and int(t.max()) == int(t.min()):
        return None   # a constant negative law: its down thresholds lie past the last byte
    down = [int(np.argmax(t > -level)) for level in range(1, max(-int(t.min()), 0) + 1)]
    return up, down


def _count_ir(up, down) -> str:
    """A portable kernel (any LLVM vector target: SSE, AVX2, NEON) for one
    non-decreasing one-byte law: its look-up as counts of constant thresholds."""
    def splat8(v):
        return "<" + ", ".join([f"i8 {v}"] * 64) + ">"

    def count(tag, cmp, thresholds, out):  # %out = how many thresholds the byte passes
        acc, ir = "zeroinitializer", ""
        for j, v in enumerate(thresholds):
            ir += (f"  %{tag}u{j} = icmp {cmp} <64 x i8> %b, {splat8(v)}\n"
                   f"  %{tag}z{j} = zext <64 x i1> %{tag}u{j} to <64 x i8>\n"
                   f"  %{tag}a{j} = add <64 x i8> {acc}, %{tag}z{j}\n")
            acc = f"%{tag}a{j}"
        return ir + f"  %{out} = add <64 x i8> {acc}, zeroinitializer\n"

    body = "  %w0 = mul i64 %i, 8\n" + _words_ir("b", "%w0")
    body += count("p", "uge", up, "pos") + count("q", "ult", down, "neg")
    return _function_ir("", body)


_KERNELS: dict = {}
_ENGINES: list = []      # kept alive: the kernels' machine code lives in them


def _compile(two: bool, counts=None):
    """The compiled kernel as a ctypes function, or None where it cannot run
    (no AVX-512 VBMI for the table kernel, llvmlite missing or refusing).
    ``counts``: ``(up, down)`` thresholds of a one-byte law, the portable kernel."""
    try:
        import llvmlite.binding as llvm

        flat = llvm.get_host_cpu_features().flatten()
        # The VBMI IR aborts the interpreter (an LLVM error, not an
        # exception) on a target without it: the same feature string the
        # target machine gets must carry it.
        if counts is None and "+avx512vbmi" not in flat.split(","):
            return None
        try:
            llvm.initialize_native_target()
            llvm.initialize_native_asmprinter()
        except RuntimeError:   # initialised already (numba, another kernel)
            pass
        mod = llvm.parse_assembly(_kernel_ir(two) if counts is None else _count_ir(*counts))
        mod.verify()
        target = llvm.Target.from_default_triple()
        tm = target.create_target_machine(cpu=llvm.get_host_cpu_name(), features=flat, opt=3)
        engine = llvm.create_mcjit_compiler(mod, tm)
        engine.finalize_object()
        _ENGINES.append(engine)
        addr = engine.get_function_address("add_noise")
    except Exception:   # any failure: OpenCV's passes over the same stream draw the same frames
        return None
    proto = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p,
                             ctypes.c_uint64)
    return proto(addr)


# Environment override of the implementation (the frames are the same):
# "auto" (compiled kernels where they run), "opencv", "reference" (numpy).
NOISE_ENV = "CUESPIN_NOISE"
# A law with more thresholds than this (sigma above ~12) is left to OpenCV:
# the portable kernel's cost grows with their number.
MAX_COUNT_THRESHOLDS = 64


def kernel(two: bool):
    """The AVX-512 VBMI kernel for a one- or two-byte law (None if unavailable), compiled once per process."""
    if two not in _KERNELS:
        _KERNELS[two] = _compile(two)
    return _KERNELS[two]


def count_kernel(tables: np.ndarray):
    """The portable kernel of a one-byte law (None if the law is not
    non-decreasing, has too many thresholds, or cannot be compiled), once per law."""
    key = ("count", tables.tobytes())
    if key not in _KERNELS:
        counts = count_thresholds(tables[0].view(np.int8))
        ok = counts is not None and len(counts[0]) + len(counts[1]) <= MAX_COUNT_THRESHOLDS
        _KERNELS[key] = _compile(False, counts) if ok else None
    return _KERNELS[key]


def add_noise(img: np.ndarray, tables: np.ndarray, seed: int, two: bool,
              out: np.ndarray | None = None, compiled: bool = True) -> np.ndarray:
    """``clip(img + n, 0, 255)`` with fresh noise ``n`` per pixel and channel from ``seed``.

    Parameters
    ----------
    img : ndarray of uint8
        Any shape; read only.
    tables : ndarray of uint8, shape (3, 256)
        The law: ``A`` (int8 values as bytes), ``T``, ``D``.
    seed : int
        64-bit seed of the frame's stream.
    two : bool
        Two bytes per pixel (``n = A[b] + (c >= T[b]) D[b]``) or one (``A[b]``).
    out : ndarray of uint8, optional
        Written in place (img's shape, C-contiguous; may not be ``img``).
    compiled : bool
        Use the compiled kernel where it runs, else OpenCV (False: the numpy reference).

    Returns
    -------
    ndarray of uint8
        ``out``, or a new array.
    """
    choice = os.environ.get(NOISE_ENV, "auto")
    compiled = compiled and choice != "reference"
    fn = kernel(two) if compiled and choice == "auto" else None
    if fn is None and compiled and choice == "auto" and not two:
        fn = count_kernel(np.ascontiguousarray(tables, dtype=np.uint8))
    if fn is None:
        res = (add_noise_opencv if compiled else add_noise_reference)(img, tables, seed, two)
        if out is None:
            return res
        out[...] = res
        return out
    return run_kernel(fn, img, tables, seed, two, out)


def run_kernel(fn, img: np.ndarray, tables: np.ndarray, seed: int, two: bool,
               out: np.ndarray | None = None) -> np.ndarray:
    """:func:`add_noise` through the compiled kernel ``fn`` (of the law's kind, ``two``)."""
    src = np.ascontiguousarray(img, dtype=np.uint8)
    if out is None:
        out = np.empty_like(src)
    elif out.shape != src.shape or out.dtype != np.uint8 or not out.flags.c_contiguous:
        raise ValueError("out must be a C-contiguous uint8 array of the image's shape")
    tab = np.ascontiguousarray(tables, dtype=np.uint8)
    n = src.size
    full = n // CHUNK
    seed = int(seed) & 0xFFFFFFFFFFFFFFFF
    fn(src.ctypes.data, out.ctypes.data, full, tab.ctypes.data, seed)
    rest = n - full * CHUNK
    if rest:
        # The last chunk through a padded copy; its stream starts at word
        # full * per: the counter is seed + (k + 1) G, so a seed shifted by
        # full * per * G reads on from there.
        per = 16 if two else 8
        pad = np.zeros(CHUNK, np.uint8)
        pad[:rest] = src.reshape(-1)[full * CHUNK:]
        res = np.empty(CHUNK, np.uint8)
        fn(pad.ctypes.data, res.ctypes.data, 1, tab.ctypes.data,
           (seed + full * per * GOLDEN) & 0xFFFFFFFFFFFFFFFF)
        out.reshape(-1)[full * CHUNK:] = res[:rest]
    return out
