"""Launching a kernel with its arguments given by name.

A kernel's parameter list is its argument list, written once: :func:`launch` takes the arguments as keywords named like
the kernel's parameters, orders them as the kernel declares them and refuses a missing or unknown name. The launch
functions beside each kernel family call it, so a setting carries one name from its caller to the kernel argument.

On the CPU a launch repeated with the same arrays and values (a step's small launches, thousands per run) replays a
recorded launch (:func:`launch_inputs`): ``wp.launch`` checks and packs every argument again on each call, some 20 us
of Python for a kernel of ten arguments, where a recorded launch replays in about 3 us.
"""

import ctypes
import threading

import warp as wp

_NAMES: dict = {}  # kernel -> its parameter names (kernels live as long as the process)

RECORDED_PER_KERNEL = 4
"""Recorded launches kept per kernel (argument sets in use at once: one per solver or state that launches it)."""

_recorded: dict = {}  # kernel -> {key: (recorded launch, inputs)}, oldest first, at most RECORDED_PER_KERNEL
_seen: dict = {}  # kernel -> the key of its last launch that was not replayed
_recorded_lock = threading.Lock()


def argument_names(kernel) -> tuple[str, ...]:
    """The names of ``kernel``'s parameters, in order."""
    names = _NAMES.get(kernel)
    if names is None:
        names = _NAMES[kernel] = tuple(a.label for a in kernel.adj.args)
    return names


def launch(kernel, dim, *, device, record_cmd: bool = False, **arguments):
    """``wp.launch(kernel, dim, inputs, device)`` with the inputs given by parameter name (each exactly once; a
    TypeError names what is missing or unknown), through :func:`launch_inputs`. With ``record_cmd``, returns the
    recorded launch without running it (``wp.launch(..., record_cmd=True)``)."""
    names = argument_names(kernel)
    if len(arguments) != len(names) or not all(n in arguments for n in names):
        missing = [n for n in names if n not in arguments]
        unknown = [n for n in arguments if n not in names]
        raise TypeError(f"kernel {kernel.key}: missing arguments {missing}, unknown arguments {unknown}")
    inputs = [arguments[n] for n in names]
    if record_cmd:
        return wp.launch(kernel, dim=dim, inputs=inputs, device=device, record_cmd=True)
    launch_inputs(kernel, dim, inputs, device)
    return None


def launch_wrapped() -> bool:
    """Whether ``wp.launch`` is a tool's wrapper (one that records or times launches: pdsim/explain.py,
    tools/bench_pd_throughput.py) rather than Warp's own; launches then go through it, never replayed."""
    return not getattr(wp.launch, "__module__", "").startswith("warp.")


def launch_inputs(kernel, dim, inputs: list, device) -> None:
    """``wp.launch(kernel, dim=dim, inputs=inputs, device=device)``; on the CPU, the second launch of ``kernel`` in a
    row with the same arrays (by identity) and the same values (bit for bit) records the launch, and later launches
    with those inputs replay the recording, which runs the same compiled kernel on the same arguments. Launches go
    through ``wp.launch`` on a CUDA device, while the device records a graph (pdsim/capture.py), while a tool wraps
    ``wp.launch``, and with an argument that is neither an array, a number nor a Warp scalar, vector or matrix. A
    recorded launch holds its inputs, so the identity of an array in its key cannot be taken by a new array while it
    is kept."""
    device = wp.get_device(device)
    key = _inputs_key(dim, inputs) if device.is_cpu else None
    if key is None or device.is_capturing or launch_wrapped():
        wp.launch(kernel, dim=dim, inputs=inputs, device=device)
        return
    entries = _recorded.get(kernel)
    entry = entries.get(key) if entries is not None else None
    if entry is None:
        if _seen.get(kernel) != key:  # a launch not (yet) repeated: plain, its key noted
            _seen[kernel] = key
            wp.launch(kernel, dim=dim, inputs=inputs, device=device)
            return
        entry = (wp.launch(kernel, dim=dim, inputs=inputs, device=device, record_cmd=True), list(inputs))
        with _recorded_lock:
            entries = _recorded.setdefault(kernel, {})
            if len(entries) >= RECORDED_PER_KERNEL:
                entries.pop(next(iter(entries)))
            entries[key] = entry
    entry[0].launch()


def _inputs_key(dim, inputs: list):
    """What a recorded launch of ``inputs`` over ``dim`` depends on: the launch dimension, each array's identity, each
    number's type and value (floats and Warp scalars, vectors and matrices by their bits: 0.0 and -0.0 differ), or
    None when an input is of another kind or the launch is empty (not replayed)."""
    if type(dim) is int:
        if dim <= 0:
            return None
    elif type(dim) is tuple and dim and all(type(d) is int and d > 0 for d in dim):
        pass
    else:
        return None
    key = [dim]
    for x in inputs:
        t = type(x)
        if isinstance(x, wp.array):
            key.append(id(x))
        elif t is int or t is bool:
            key.append((t, x))
        elif t is float:
            key.append((t, x.hex()))
        elif isinstance(x, ctypes.Array):  # Warp vectors, matrices, quaternions, transforms
            key.append((t, bytes(x)))
        elif wp.types.type_is_scalar(t):
            value = x.value
            key.append((t, value.hex() if type(value) is float else value))
        else:
            return None
    return tuple(key)


def range_inputs(kernel, arguments: dict) -> list:
    """The inputs of a range kernel (one whose first parameter, ``first``, is the first point of its launch) after
    ``first``, in the order the kernel declares them, from ``arguments`` given by parameter name (each exactly once; a
    TypeError names what is missing or unknown)."""
    names = argument_names(kernel)[1:]
    if sorted(arguments) != sorted(names):
        raise TypeError(f"kernel {kernel.key}: arguments missing or unknown: {sorted(set(names) ^ set(arguments))}")
    return [arguments[n] for n in names]


def by_name(source, *names: str) -> dict:
    """{name: source.name} for each of ``names``: the arrays and settings that ``source`` holds under the names of the
    kernel parameters they go to, as keyword arguments of :func:`launch`."""
    return {name: getattr(source, name) for name in names}
