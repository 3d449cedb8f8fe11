"""How the kernels are compiled where Numba's reference counting would cost more than their arithmetic.

Numba counts a reference to an array each time a variable or a called function takes it: an atomic
increment and decrement that LLVM cannot always remove, and after which it reloads whatever the kernel
reads. :func:`borrowing` compiles a called element without the counting; :class:`ForwardCopiesCompiler`
compiles a kernel with the array copies its inlined elements make forwarded away (:func:`forward_array_copies`).
:data:`unlikely` marks a rare branch, so LLVM keeps it a branch instead of a select on the kernel's critical path.
None changes an operation on a number, so the outputs are the same bit for bit. They use Numba's compiler
interfaces (``numba.core``), which requirements.txt pins.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, TypeVar, cast, overload

import numba as nb
from llvmlite import ir as llvm_ir  # type: ignore[import-untyped]
from numba.core import cgutils, ir, ir_utils, types
from numba.core.analysis import compute_cfg_from_blocks
from numba.core.base import BaseContext
from numba.core.compiler import CompilerBase, DefaultPassBuilder, StateDict
from numba.core.compiler_machinery import FunctionPass, PassManager, register_pass
from numba.core.typed_passes import NopythonRewrites
from numba.core.typing.context import BaseContext as TypingContext
from numba.core.typing.templates import Signature
from numba.extending import intrinsic

_F = TypeVar("_F", bound=Callable[..., object])


@overload
def borrowing(fn: _F, /) -> _F: ...


@overload
def borrowing(*, nogil: bool = ..., error_model: Literal["python", "numpy"] = ...,
              fastmath: bool | set[str] = ...) -> Callable[[_F], _F]: ...


def borrowing(fn: _F | None = None, /, *, nogil: bool = False, error_model: Literal["python", "numpy"] = "python",
              fastmath: bool | set[str] = False) -> _F | Callable[[_F], _F]:
    """Compile a called (not inlined) element that works only in arrays its caller owns, without Numba's runtime.

    Numba counts a reference to each array argument on entry to a compiled function and releases it on
    exit: two atomic operations per array per call, which LLVM cannot remove when a function takes several
    arrays. An RK4 step called a few thousand times a simulated second with nine arrays spent most of its
    time there. Without the runtime the arguments are borrowed, which is safe because the caller holds
    them for the call; an element that allocates an array does not compile this way (a typing error, not a
    leak), so it cannot be used by mistake. ``@borrowing`` alone, or ``@borrowing(...)`` with Numba's options.

    Parameters
    ----------
    fn : callable, optional
        The element (without it: the decorator with these options).
    nogil : bool
        Release the GIL while it runs (an entry point called from Python threads).
    error_model : str
        Numba's error model.
    fastmath : bool or set of str
        Numba's floating-point flags.

    Returns
    -------
    numba dispatcher or callable
        ``fn`` compiled and cached, without reference counting; or the decorator.
    """

    def compile_(f: _F) -> _F:
        compiled: _F = nb.njit(cache=True, _nrt=False, nogil=nogil, error_model=error_model, fastmath=fastmath)(f)
        return compiled

    return compile_ if fn is None else compile_(fn)


def forward_array_copies(blocks: dict[int, ir.Block], typemap: dict[str, types.Type]) -> int:
    """Replace every array variable that only copies another by that one, in a typed function's Numba IR.

    An element inlined into a kernel binds its array arguments to variables of its own (``p = params_i``).
    Numba counts a reference for each such variable, an atomic increment when it is bound and a decrement
    after its last use, and its reference-count pruning in LLVM removes the pair only in simple shapes: after
    an element's branches (:func:`~ema_sim.models.second_order.figure26.write_outputs`' ``or``) the decrements
    sit on several paths and stay. LOADA's sample loop made three ``NRT_incref`` and five ``NRT_decref``
    calls per sample, and as the calls are opaque to LLVM it reloaded every parameter and state it read
    after them. Numba's parfor passes propagate these copies away, which is why a ``parallel=True``
    compilation ran the same serial loop 1.7 to 3.4 times faster; this pass is only that propagation, a few
    milliseconds of a compilation.

    A copy ``t = v`` is forwarded when both are arrays of one type, each is assigned exactly once in the
    function, and each one's assignment comes before every use of it on every path (it dominates them): then
    ``t`` holds ``v``'s value wherever it is read. The arithmetic is untouched, so results are the same bit for
    bit.

    Parameters
    ----------
    blocks : dict
        The function's IR blocks by label, changed in place.
    typemap : dict
        The type of each variable, by name.

    Returns
    -------
    int
        The copies removed.
    """
    copies, where = _array_copies(blocks, typemap)
    if not copies:
        return 0
    dominators = compute_cfg_from_blocks(blocks).dominators()  # type: ignore[no-untyped-call]

    def before(at: tuple[int, int], label: int, k: int) -> bool:
        return at[0] in dominators[label] and (at[0] != label or at[1] < k)

    unsafe: set[str] = set()
    found: dict[str, ir.Var] = {}
    for label, block in blocks.items():
        for k, stmt in enumerate(block.body):
            defined = stmt.target.name if isinstance(stmt, ir.Assign) else None
            for var in stmt.list_vars():
                found.setdefault(var.name, var)
                name = var.name
                if name in copies and not before(where[copies[name] if name == defined else name], label, k):
                    unsafe.add(name)
    for name in unsafe:
        del copies[name]
    root: dict[str, ir.Var] = {}
    for t, v in copies.items():
        source = v
        while source in copies:
            source = copies[source]
        root[t] = found[source]
    for block in blocks.values():
        block.body = [stmt for stmt in block.body if not (isinstance(stmt, ir.Assign) and stmt.target.name in root)]
    ir_utils.replace_vars(blocks, root)  # type: ignore[no-untyped-call]
    return len(root)


def _array_copies(blocks: dict[int, ir.Block],
                  typemap: dict[str, types.Type]) -> tuple[dict[str, str], dict[str, tuple[int, int]]]:
    """The candidates of :func:`forward_array_copies`: array copies between variables assigned once.

    Parameters
    ----------
    blocks : dict
        The function's IR blocks by label.
    typemap : dict
        The type of each variable, by name.

    Returns
    -------
    copies : dict
        The variable each copy reads, by the copy's name.
    where : dict
        Where each variable is assigned (its last assignment): block label, statement index.
    """
    defs: dict[str, int] = {}
    where: dict[str, tuple[int, int]] = {}
    copies: dict[str, str] = {}
    for label, block in blocks.items():
        for k, stmt in enumerate(block.body):
            if isinstance(stmt, ir.Assign):
                defs[stmt.target.name] = defs.get(stmt.target.name, 0) + 1
                where[stmt.target.name] = (label, k)
                if isinstance(stmt.value, ir.Var):
                    copies[stmt.target.name] = stmt.value.name
    copies = {t: v for t, v in copies.items() if isinstance(typemap.get(t), types.Array) and t != v
              and typemap.get(v) == typemap[t] and defs[t] == 1 and defs.get(v) == 1}
    return copies, where


@register_pass(mutates_CFG=False, analysis_only=False)  # type: ignore[no-untyped-call]
class ForwardArrayCopies(FunctionPass):
    """The compiler pass of :func:`forward_array_copies`, run on the typed IR after Numba's rewrites."""

    _name = "ema_forward_array_copies"

    def __init__(self) -> None:
        FunctionPass.__init__(self)  # type: ignore[no-untyped-call]

    def run_pass(self, state: StateDict) -> bool:
        """Forward the function's array copies.

        Parameters
        ----------
        state : numba.core.compiler.StateDict
            The compilation's state: its IR and type map.

        Returns
        -------
        bool
            Whether the IR changed.
        """
        if forward_array_copies(state.func_ir.blocks, state.typemap) == 0:
            return False
        state.func_ir._definitions = ir_utils.build_definitions(state.func_ir.blocks)  # type: ignore[no-untyped-call]
        return True


class ForwardCopiesCompiler(CompilerBase):
    """Numba's nopython pipeline with :class:`ForwardArrayCopies` after its rewrites."""

    def define_pipelines(self) -> list[PassManager]:
        """The one pipeline.

        Returns
        -------
        list
            Numba's nopython pass manager, the pass added.
        """
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)  # type: ignore[no-untyped-call]
        pm.add_pass_after(ForwardArrayCopies, NopythonRewrites)
        pm.finalize()
        return [pm]


def _expect_false(_typingctx: TypingContext, condition: types.Type
                  ) -> tuple[Signature, Callable[[BaseContext, Any, Signature, list[object]], Any]] | None:
    """Typing and code of :data:`unlikely`: the condition unchanged, with LLVM told it is almost always false.

    Parameters
    ----------
    _typingctx : numba.core.typing.Context
        Numba's typing context (unused).
    condition : numba.core.types.Type
        The argument's type (a boolean).

    Returns
    -------
    tuple or None
        The signature and its code generator; None for a non-boolean argument.
    """
    if not isinstance(condition, types.Boolean):
        return None

    def codegen(_context: BaseContext, builder: Any, _signature: Signature, args: list[object]) -> object:
        i1 = llvm_ir.IntType(1)
        expect = cgutils.get_or_insert_function(  # type: ignore[no-untyped-call]
            builder.module, llvm_ir.FunctionType(i1, [i1, i1]), "llvm.expect.i1")
        return builder.call(expect, [args[0], llvm_ir.Constant(i1, 0)])

    return types.boolean(types.boolean), codegen


def _row_values(_typingctx: TypingContext, row: types.Type, length: types.Type
                ) -> tuple[Signature, Callable[[BaseContext, Any, Signature, list[object]], Any]] | None:
    """Typing and code of :data:`row_values`: ``length`` loads from a contiguous row, as one tuple.

    Parameters
    ----------
    _typingctx : numba.core.typing.Context
        Numba's typing context (unused).
    row : numba.core.types.Type
        The row's type (a C-contiguous one-dimensional array).
    length : numba.core.types.Type
        The length's type (an integer literal).

    Returns
    -------
    tuple or None
        The signature and its code generator; None for other argument types.
    """
    if not (isinstance(row, types.Array) and row.ndim == 1 and row.layout == "C"
            and isinstance(length, types.IntegerLiteral)):
        return None
    tuple_type = types.UniTuple(row.dtype, int(length.literal_value))  # type: ignore[no-untyped-call]

    def codegen(context: BaseContext, builder: Any, signature: Signature, args: list[object]) -> object:
        data = context.make_array(signature.args[0])(context, builder, args[0]).data  # type: ignore[no-untyped-call]
        values = [builder.load(cgutils.gep_inbounds(builder, data, k))  # type: ignore[no-untyped-call]
                  for k in range(tuple_type.count)]
        return context.make_tuple(builder, tuple_type, values)  # type: ignore[no-untyped-call]

    return tuple_type(row, length), codegen


row_values = cast("Callable[..., Any]", intrinsic(_row_values))
"""``row_values(row, length)`` in a kernel: the first ``length`` values of a contiguous row (it must hold them) as a
tuple, one load each. A kernel that takes its parameters this way holds them as values rather than memory, so what
it derives from them is computed once, not again after each store of a state. (Numba's ``to_fixed_tuple`` builds
the tuple in a loop that copies it whole per element: thousands of instructions for a row of 33.)"""


unlikely = cast("Callable[[bool], bool]", intrinsic(_expect_false))
"""``unlikely(condition)`` in a kernel: the condition, with the branch it decides weighted as rarely taken.

``llvm.expect`` becomes branch weights, and LLVM then keeps the branch rather than computing both sides and
selecting (a select waits for its condition, a predicted branch does not). The stick test after each division
in :func:`~ema_sim.models.high_order.figure30.friction_step` was such a select: on the serial path of HOAD3's
step, about 10 % of its time. Only code layout changes, never an operation on a number, so the results are the
same bit for bit.
"""
