"""Launching a kernel with its arguments given by name.

A kernel's parameter list is its argument list, written once: :func:`launch` takes the arguments as keywords named like
the kernel's parameters, orders them as the kernel declares them and refuses a missing or unknown name. The launch
functions beside each kernel family call it, so a setting carries one name from its caller to the kernel argument.
"""

import warp as wp

_NAMES: dict = {}  # kernel -> its parameter names (kernels live as long as the process)


def argument_names(kernel) -> tuple[str, ...]:
    """The names of ``kernel``'s parameters, in order."""
    names = _NAMES.get(kernel)
    if names is None:
        names = _NAMES[kernel] = tuple(a.label for a in kernel.adj.args)
    return names


def launch(kernel, dim, *, device, record_cmd: bool = False, **arguments):
    """``wp.launch(kernel, dim, inputs, device)`` with the inputs given by parameter name (each exactly once; a
    TypeError names what is missing or unknown). Returns what ``wp.launch`` returns (with ``record_cmd``, the
    recorded launch)."""
    names = argument_names(kernel)
    if len(arguments) != len(names) or not all(n in arguments for n in names):
        missing = [n for n in names if n not in arguments]
        unknown = [n for n in arguments if n not in names]
        raise TypeError(f"kernel {kernel.key}: missing arguments {missing}, unknown arguments {unknown}")
    return wp.launch(kernel, dim=dim, inputs=[arguments[n] for n in names], device=device, record_cmd=record_cmd)


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
