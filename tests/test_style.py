"""The code's own conventions, checked: public functions carry type hints (issue 14)."""

import importlib
import inspect
import pkgutil

import simbench


def _public_functions():
    for info in pkgutil.walk_packages(simbench.__path__, "simbench."):
        if info.name.split(".")[-1].startswith("_") or info.name == "simbench.cli":
            continue  # private modules (the C kernels' wrappers); the CLI's functions are argparse glue
        module = importlib.import_module(info.name)
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            if inspect.isfunction(obj) and obj.__module__ == module.__name__:
                yield f"{info.name}.{name}", obj


def test_public_functions_have_type_hints():
    missing = []
    for qualname, fn in _public_functions():
        sig = inspect.signature(fn)
        untyped = [p.name for p in sig.parameters.values() if p.annotation is inspect.Parameter.empty]
        if untyped or sig.return_annotation is inspect.Signature.empty:
            missing.append(
                f"{qualname}: "
                f"{untyped or ''}{' no return type' if sig.return_annotation is inspect.Signature.empty else ''}"
            )
    assert not missing, "public functions without type hints:\n" + "\n".join(missing)
