"""The writers' positional arguments in HOOMD-blue's order (docs/hoomd.md)."""


def trigger_first(writer, args, trigger, target, default_trigger, target_name):
    """A writer's ``(trigger, target)`` from up to two positional ``args``, in HOOMD-blue's order
    (``hoomd.write.GSD(trigger, filename)``), the keywords ``trigger`` and ``target_name`` filling
    what is not given. The order of spherevm 0.1, a path first (``GSD("run.gsd", trigger=100)``),
    still works and warns."""
    import os
    import warnings
    if len(args) > 2:
        raise TypeError(f"{writer}() takes at most 2 positional arguments (trigger, {target_name}), got {len(args)}")
    if args and isinstance(args[0], (str, os.PathLike)):
        warnings.warn(f"{writer}(path, trigger) is the old argument order; write {writer}(trigger, path) as "
                      "HOOMD-blue does, or use keywords", DeprecationWarning, stacklevel=3)
        args = tuple(reversed(args)) if len(args) == 2 else (None,) + args
    args = tuple(args) + (None,) * (2 - len(args))
    out = []
    for name, by_position, by_keyword in (("trigger", args[0], trigger), (target_name, args[1], target)):
        if by_position is not None and by_keyword is not None:
            raise TypeError(f"{writer}() got {name} both by position and by keyword")
        out.append(by_keyword if by_position is None else by_position)
    return (default_trigger if out[0] is None else out[0]), out[1]
