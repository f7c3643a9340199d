"""adaptive_mj.numba_util.shared_inline_copies: numba's inliner copies a function's IR with one memo for all its
blocks (a third to a half of a controller's cold compile), and the code it compiles is the same."""
import json
import os
import subprocess
import sys
import textwrap

from adaptive_mj import numba_util

# A tree of inline="always" functions with branches (many blocks), a loop, an array argument, and two call sites of
# the same callee: what the controllers' pieces look like to numba's inliner. Each process compiles it afresh
# (cache off) and prints its results, and the machine code's size with its text's hash.
PROGRAM = textwrap.dedent("""
    import hashlib, json, sys
    import numpy as np
    import numba
    from adaptive_mj import numba_util

    installed = numba_util.shared_inline_copies()
    inline = numba.njit(inline="always")

    @inline
    def clip(v, lo, hi):
        if v < lo:
            return lo
        if v > hi:
            return hi
        return v

    @inline
    def stage(x, k, out):
        acc = 0.0
        for i in range(x.shape[0]):
            if x[i] > 0.0:
                acc += clip(k * x[i], -1.0, 2.0)
            elif x[i] < -0.5:
                acc -= clip(x[i] * x[i], 0.0, 0.3)
            else:
                acc += 0.25 * x[i]
        out[0] = acc
        return acc

    @numba.njit
    def outer(x, k):
        out = np.zeros(1)
        a = stage(x, k, out)          # the same callee at two sites: two copies of its IR
        b = stage(x[::-1], 2.0 * k, out)
        return a, b, out[0]

    x = np.linspace(-1.0, 1.0, 9)
    r = outer(x, 0.7)
    asm = outer.inspect_asm(outer.signatures[0])
    print(json.dumps({"installed": installed, "r": [v.hex() for v in r],
                      "asm": hashlib.sha256(asm.encode()).hexdigest()}))
""")


def _compiled(shared: str) -> dict:
    env = {**os.environ, "ADAPTIVE_MJ_SHARED_INLINE_COPIES": shared}
    r = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_shared_copies_compile_the_same_code_as_numba_alone():
    shared, alone = _compiled("1"), _compiled("0")
    assert shared["installed"] is True and alone["installed"] is False
    # the values by hand: stage(x, 0.7) over x = -1, -0.75, ..., 1 and stage(x reversed, 1.4)
    x = [-1.0 + 0.25 * i for i in range(9)]

    def stage(xs, k):
        acc = 0.0
        for v in xs:
            if v > 0.0:
                acc += min(max(k * v, -1.0), 2.0)
            elif v < -0.5:
                acc -= min(max(v * v, 0.0), 0.3)
            else:
                acc += 0.25 * v
        return acc

    a, b = stage(x, 0.7), stage(x[::-1], 1.4)
    assert shared["r"] == alone["r"] == [a.hex(), b.hex(), b.hex()]
    assert shared["asm"] == alone["asm"]


def test_numba_is_left_as_it_is_where_its_inliner_copies_otherwise(monkeypatch):
    """A numba whose inline_ir no longer holds the line the shim reads: nothing is replaced (False)."""
    from numba.core import inline_closurecall, ir

    monkeypatch.setattr(numba_util, "_inline_copies", {})
    monkeypatch.setattr(numba_util, "INLINE_COPY_SOURCE", "a line numba does not have")
    copy_module, function_ir_copy = inline_closurecall.copy, ir.FunctionIR.copy
    monkeypatch.delenv("ADAPTIVE_MJ_SHARED_INLINE_COPIES", raising=False)
    assert numba_util.shared_inline_copies() is False
    assert inline_closurecall.copy is copy_module and ir.FunctionIR.copy is function_ir_copy


def test_two_copies_of_one_function_share_no_object():
    """Within one copy_ir call the blocks share a memo; two calls (the inliner's two copies of a callee) do not."""
    code = textwrap.dedent("""
        import json
        import numba
        from numba.core import inline_closurecall, ir
        from numba.core.compiler import run_frontend
        from adaptive_mj import numba_util
        assert numba_util.shared_inline_copies()

        def f(a):
            if a > 0:
                b = a + 1
            else:
                b = a - 1
            return b

        fir = run_frontend(f)
        def copy_ir(the_ir):  # numba's, as inline_ir runs it
            kernel_copy = the_ir.copy()
            kernel_copy.blocks = {}
            for label, block in the_ir.blocks.items():
                kernel_copy.blocks[label] = inline_closurecall.copy.deepcopy(the_ir.blocks[label])
            return kernel_copy
        one, two = copy_ir(fir), copy_ir(fir)
        scopes = lambda i: {id(b.scope) for b in i.blocks.values()}
        print(json.dumps({"blocks": len(fir.blocks), "one": len(scopes(one)), "two": len(scopes(two)),
                          "shared": len(scopes(one) & scopes(two)),
                          "original": len(scopes(one) & scopes(fir))}))
    """)
    env = {**os.environ, "ADAPTIVE_MJ_SHARED_INLINE_COPIES": "1"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["blocks"] >= 3  # branches: several blocks, one scope in the original
    assert got == {"blocks": got["blocks"], "one": 1, "two": 1, "shared": 0, "original": 0}
