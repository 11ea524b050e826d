"""Kernels compiled apart and called at their addresses (`call_at`): a caller compiled without its
callee's code. numba links a callee's code into each caller and optimizes it again there, so
that a step loop calling every phase and term directly is one compile of all of them, again for
each caller. Called at an address, a kernel compiles once, apart, only for a model that calls it
(`kernel_address`), without the entry point Python would call (`ADDRESS_ONLY`), its large
arguments read from the caller's frame (`args_in_memory`, `args_from_memory`); on a first run
with a second core free, the largest is compiled by a helper process meanwhile (`compile_elsewhere`).
"""

from __future__ import annotations

import atexit
import os
import pickle
import subprocess
import sys

import numba
from llvmlite import ir as llvm_ir
from numba.core import cgutils
from numba.core import types as nb_types
from numba.extending import intrinsic

from .kernel import cached_signatures

__all__ = [
    "call_at",
    "call_c",
    "kernel_address",
    "ADDRESS_ONLY",
    "args_in_memory",
    "args_type_of",
    "args_from_memory",
    "is_cached",
    "compile_elsewhere",
]


@intrinsic
def call_c(typingctx, fn, args):
    """Call the C function `void f(...)` at address fn with the tuple args: an int64 or a pointer
    as a 64-bit word, an int32 as a C int, a float64 as a double, an array as its data's address
    (MuJoCo's functions, whose addresses the step's pack carries: `hybrid.loop.MjViews`), so that
    the compiled code names no symbol and its cache loads in any process.
    # Data in: fn (int64), args (a tuple)   # Data out: whatever f writes
    """

    def codegen(context, builder, signature, llargs):
        values = cgutils.unpack_tuple(builder, llargs[1], len(args.types))
        word = llvm_ir.IntType(64)
        kinds, passed = [], []
        for ty, v in zip(args.types, values):
            ty = nb_types.unliteral(ty)
            if isinstance(ty, nb_types.Array):
                data = context.make_array(ty)(context, builder, v).data
                kinds.append(word)
                passed.append(builder.ptrtoint(data, word))
            elif ty == nb_types.float64:
                kinds.append(llvm_ir.DoubleType())
                passed.append(v)
            elif ty == nb_types.int32:
                kinds.append(llvm_ir.IntType(32))
                passed.append(v)
            else:
                kinds.append(word)
                passed.append(v)
        target = builder.inttoptr(llargs[0], llvm_ir.FunctionType(llvm_ir.VoidType(), kinds).as_pointer())
        builder.call(target, passed)
        return context.get_dummy_value()

    for ty in args.types:
        ty = nb_types.unliteral(ty)
        if not (
            isinstance(ty, nb_types.Array) or ty in (nb_types.float64, nb_types.int32, nb_types.int64, nb_types.intp)
        ):
            return None
    return nb_types.void(fn, args), codegen


@intrinsic
def call_at(typingctx, address, result, args):
    """The kernel compiled at `address` (`kernel_address`) called with the tuple `args`; its result,
    of `result`'s type. The caller is compiled without the kernel's code: numba links a callee's
    code into each caller and optimizes it again there, so that implicit Euler's whole solve was
    compiled into the step loop, a loop build of its own (76 s of CPU for a first implicit run).
    Called this way it compiles once, apart, beside the one loop every solver shares. The
    kernel must have been compiled for exactly args' types and result's (`kernel_address` takes
    them from the same arrays); an address of 0 must never be called.
    # Data in: address (int64), result (a value of the result's type), args (a tuple)   # Data out: returns result's type
    """
    result_type = nb_types.unliteral(result)
    arg_types = tuple(nb_types.unliteral(t) for t in args.types)

    def codegen(context, builder, signature, llargs):
        fn_type = context.call_conv.get_function_type(result_type, arg_types).as_pointer()
        fn = builder.inttoptr(llargs[0], fn_type)
        values = cgutils.unpack_tuple(builder, llargs[2], len(arg_types))
        status, res = context.call_conv.call_function(builder, fn, result_type, arg_types, values)
        with cgutils.if_unlikely(builder, status.is_error):
            context.call_conv.return_status_propagate(builder, status)
        return res

    return result_type(address, result, args), codegen


def _store_leaves(builder, value, ptr):
    """Store an aggregate field by field: LLVM copies a large aggregate stored or loaded whole
    (thousands of words a call) where a field at a time lets it drop the fields never read."""
    ty = value.type
    if isinstance(ty, (llvm_ir.LiteralStructType, llvm_ir.IdentifiedStructType)):
        for i in range(len(ty.elements)):
            _store_leaves(builder, builder.extract_value(value, i), cgutils.gep_inbounds(builder, ptr, 0, i))
    else:
        builder.store(value, ptr)


def _load_leaves(builder, ptr):
    """Load an aggregate field by field (`_store_leaves`)."""
    ty = ptr.type.pointee
    if isinstance(ty, (llvm_ir.LiteralStructType, llvm_ir.IdentifiedStructType)):
        value = cgutils.get_null_value(ty)
        for i in range(len(ty.elements)):
            value = builder.insert_value(value, _load_leaves(builder, cgutils.gep_inbounds(builder, ptr, 0, i)), i)
        return value
    load = builder.load(ptr)
    # unchanged while the kernel runs: LLVM may load a field again where it is used rather than
    # keep every field in a register or a spill slot from the kernel's start
    load.set_metadata("invariant.load", builder.module.add_metadata([]))
    return load


@intrinsic
def args_in_memory(typingctx, args):
    """The tuple args stored once in the caller's stack frame; returns its address (int64), which a
    kernel called at its address reads back (`args_from_memory`): a call then passes one word
    instead of every field of every array in args (numba passes each as arguments of its own:
    about a thousand for the step's arrays, 0.3 us a call). Valid until the caller returns.
    # Data in: args (a tuple)   # Data out: returns the address of its copy
    """

    def codegen(context, builder, signature, llargs):
        slot = cgutils.alloca_once(builder, context.get_value_type(args))
        _store_leaves(builder, llargs[0], slot)
        return builder.ptrtoint(slot, context.get_value_type(nb_types.int64))

    return nb_types.int64(args), codegen


@intrinsic
def args_type_of(typingctx, args):
    """The type of the tuple args, as a value (`numba.typeof` of a numba type: a `TypeRef`) that a
    kernel called at its address takes to know what `args_from_memory` reads.
    # Data in: args   # Data out: returns its type (no data)
    """

    def codegen(context, builder, signature, llargs):
        return context.get_dummy_value()

    return nb_types.TypeRef(args)(args), codegen


@intrinsic
def args_from_memory(typingctx, address, index, args_type):
    """Item `index` (a constant) of the tuple of type args_type stored at address by
    `args_in_memory`. An item at a time: LLVM splits a tuple held in a variable into its fields
    only up to about a thousand of them (the step's five tuples hold more).
    # Data in: address (int64), index, args_type (a `TypeRef`)   # Data out: returns the item
    """
    if not isinstance(index, nb_types.IntegerLiteral):
        return None
    tup = args_type.instance_type
    item = tup.types[index.literal_value]

    def codegen(context, builder, signature, llargs):
        ty = context.get_value_type(tup)
        ptr = builder.inttoptr(llargs[0], ty.as_pointer())
        # all of it readable, and unchanged while the kernel runs: LLVM may then read a field
        # where it is used instead of copying every field to the stack at the kernel's start
        size = llvm_ir.Constant(llvm_ir.IntType(64), context.get_abi_sizeof(ty))
        ptr.set_metadata("dereferenceable", builder.module.add_metadata([size]))
        value = _load_leaves(builder, cgutils.gep_inbounds(builder, ptr, 0, index.literal_value))
        if context.enable_nrt:  # a new reference, as numba counts an intrinsic's result (the step: none)
            context.nrt.incref(builder, item, value)
        return value

    return item(address, index, args_type), codegen


def kernel_address(dispatcher, result, *example_args) -> int:
    """The address of `dispatcher` compiled (or loaded from the cache) for the example arguments'
    types, returning `result` (a numba type), which `call_at` calls. Refuses a kernel whose
    result is another type (the call would read it wrongly)."""
    arg_types = tuple(numba.typeof(a) for a in example_args)
    dispatcher.compile(arg_types)
    compiled = dispatcher.overloads[arg_types]
    if nb_types.unliteral(compiled.signature.return_type) != result:
        raise TypeError(
            f"kernel_address: {dispatcher.py_func.__qualname__} returns {compiled.signature.return_type}, expected {result}"
        )
    return int(compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name))


#: `@kernel(**ADDRESS_ONLY)`: a kernel only ever called at its address, compiled without the entry
#: point through which Python calls a kernel (numba's CPython wrapper: unboxing each array of its
#: arguments' tuples, 2.3 s of a first run's CPU for a kernel given the step's arrays). Called from
#: Python, such a kernel crashes: the step loop's own (`hybrid.loop.steps_between`, `rigid_between`).
ADDRESS_ONLY = {"no_cpython_wrapper": True}


def is_cached(dispatcher, arg_types: tuple) -> bool:
    """Whether numba's disk cache holds a build of `dispatcher` for exactly these argument types
    and this source (`hybrid.kernel.cached_signatures`)."""
    return arg_types in cached_signatures(dispatcher)


class Elsewhere:
    """Builds compiled by a helper process (`compile_elsewhere`); `wait` before using them."""

    def __init__(self, process, builds):
        self.process, self.builds, self.waited = process, builds, False

    def wait(self) -> bool:
        """Wait for the helper; whether it compiled every build (else the caller compiles what
        is missing itself). While waiting, numba's compile event is on: the compile notice
        counts the wait as compiling (`hybrid.kernel.compile_notice`)."""
        from numba.core import event

        if not self.waited:  # ended or not, waited for once inside the event: its CPU is counted
            self.waited = True
            dispatcher, arg_types = self.builds[0]
            with event.trigger_event("numba:compile", data={"dispatcher": dispatcher, "args": arg_types}):
                self.process.wait()
        return self.process.returncode == 0


def compile_elsewhere(builds) -> Elsewhere | None:
    """Start compiling `builds` [(dispatcher, arg_types)] in a helper process writing numba's disk
    cache, while this process compiles others; the helper already compiling them if asked again;
    None when each is cached already, when this process may use only one core, when another
    helper of this process is still compiling (one at a time), or when HYBRID_COMPILE_HELPER is 0.
    The builds are then loaded from the cache. Compiling is a process's main thread: on a
    first run, the step's largest build (the steps between two stops, half of the compile) then
    takes the second core instead of waiting for the first."""
    if os.environ.get("HYBRID_COMPILE_HELPER", "1") == "0":
        return None
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity on this platform
        cores = os.cpu_count() or 1
    todo = [(d, t) for d, t in builds if not is_cached(d, t)]
    if cores < 2 or not todo:
        return None
    key = tuple((id(d), t) for d, t in todo)
    if key in _RUNNING:  # asked again (another simulation of the same types): the same helper
        return _RUNNING[key]
    if any(e.process.poll() is None for e in _RUNNING.values()):  # one helper at a time
        return None
    jobs = [(d.py_func.__module__, d.py_func.__qualname__, t) for d, t in todo]
    try:
        process = subprocess.Popen(
            [sys.executable, "-c", "import sys; from hybrid.calls import compile_jobs; compile_jobs(sys.stdin.buffer)"],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
        )
        process.stdin.write(pickle.dumps(jobs))
        process.stdin.close()
    except OSError:  # no process to spare: compile here
        return None
    _RUNNING[key] = Elsewhere(process, todo)
    return _RUNNING[key]


_RUNNING: dict = {}  # the helpers started, by the builds they compile


@atexit.register
def _stop_helpers() -> None:
    """A helper still compiling when the program ends (a run refused after its simulation was
    made) is stopped: nothing of this program goes on after it."""
    for elsewhere in _RUNNING.values():
        if elsewhere.process.poll() is None:
            elsewhere.process.kill()


def compile_jobs(stream) -> None:
    """The helper process of `compile_elsewhere`: compile each job read from stream."""
    import importlib

    for module, qualname, arg_types in pickle.load(stream):
        dispatcher = importlib.import_module(module)
        for name in qualname.split("."):
            dispatcher = getattr(dispatcher, name)
        dispatcher.compile(arg_types)


def compile_callees(fn, arg_types: tuple, like) -> bool:
    """Compile (or load) into the cache every kernel `fn` calls, for the types it calls them with
    at arg_types, without compiling `fn` itself: numba's front end and type inference only, which
    compile a callee as they type its call, with the flags of the kernel `like` (those a callee
    that sets none inherits: the same build as when `like` calls it). On a first run this process does this for part of the
    steps while the helper compiles them whole (`compile_elsewhere`): the helper then loads those
    callees instead of compiling them. Whether it ran (numba's internals: False where they moved)."""
    try:
        from numba.core import compiler
        from numba.core.compiler_machinery import PassManager
        from numba.core.registry import cpu_target
        from numba.core.typed_passes import NopythonTypeInference

        class TypeOnly(compiler.CompilerBase):
            def define_pipelines(self):
                pm = compiler.DefaultPassBuilder.define_untyped_pipeline(self.state)
                typed = PassManager("type only")
                typed.add_pass(NopythonTypeInference, "type inference")
                typed.passes = pm.passes + typed.passes
                typed.finalize()
                return [typed]

        options = compiler.Flags()
        cpu_target.options.parse_as_flags(options, like.targetoptions)
        compiler.compile_extra(
            cpu_target.typing_context,
            cpu_target.target_context,
            fn,
            arg_types,
            None,
            options,
            {},
            pipeline_class=TypeOnly,
        )
    except Exception:  # noqa: BLE001 - an optimisation only: the helper compiles them anyway
        return False
    return True
