"""Taichi's front end as ``taichi_frac.runtime`` readies it: the cheaper check at each
decoration answers as Taichi's own."""

from __future__ import annotations

import importlib.util
import inspect
import sys
import textwrap

from taichi.lang import kernel_impl

from taichi_frac import runtime


def _taichis_own(level):
    """Taichi 1.7's ``kernel_impl._inside_class`` as shipped (the reference): the first
    statement of the frame ``level`` up, read through ``inspect``, against its patterns."""
    try:
        frame = sys._getframe(level)
        first = inspect.getframeinfo(frame)[3][0].strip()
        return any(pattern.match(first) for pattern in kernel_impl._KERNEL_CLASS_STACKFRAME_STMT_RES)
    except Exception:  # noqa: BLE001 (as Taichi's: no source is "not in a class")
        return False


ANSWERS = []


def record(function):
    """A decorator asking both checks as Taichi's decorators do, 2 to 4 frames up (the
    decorating frame, the one running it: a module's import machinery, or a class
    statement's module frame)."""
    for level in (2, 3, 4):
        ANSWERS.append((level, kernel_impl._inside_class(level), _taichis_own(level)))
    return function


def test_the_cheaper_class_check_answers_as_taichis_own(tmp_path, monkeypatch):
    """Decorations in a module as it is imported (whose next frame is the frozen import
    machinery, which has no source), in a class body (whose next frame stands on its
    ``class`` statement) and under ``@data_oriented``: the check ``runtime`` installs gives
    Taichi's answer at every level, True where a class statement is found."""
    assert kernel_impl._inside_class.__module__ == runtime.__name__
    source = textwrap.dedent('''
        import taichi as ti
        from test_runtime_frontend import record

        @record
        def module_level():
            pass

        class Holder:
            @record
            def method(self):
                pass

        @ti.data_oriented
        class Oriented:
            @record
            def method(self):
                pass
    ''')
    (tmp_path / "decorated_module.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(sys.modules, "test_runtime_frontend", sys.modules[__name__])
    ANSWERS.clear()
    spec = importlib.util.spec_from_file_location("decorated_module", tmp_path / "decorated_module.py")
    spec.loader.exec_module(importlib.util.module_from_spec(spec))
    assert len(ANSWERS) == 9
    assert all(ours == reference for _, ours, reference in ANSWERS), ANSWERS
    assert any(ours for _, ours, _ in ANSWERS)  # (the class statements were found)


def test_the_kept_source_wrapping_gives_textwraps_text():
    """Taichi re-wraps each source line and dedents the function before parsing it at every
    call site; ``runtime`` keeps what the same text gave (after ``runtime.init``)."""
    import textwrap

    runtime.init()
    lines = ["\tif x > 0:\t# a tab inside", "        y = [i for i in range(3)]", "", "    return y  " * 3]
    for line in lines:
        assert kernel_impl.textwrap.fill(line, tabsize=4, width=9999) == textwrap.fill(line, tabsize=4, width=9999)
    text = "\n".join(lines[1:])
    assert kernel_impl.textwrap.dedent(text) == textwrap.dedent(text)
    assert kernel_impl.textwrap.fill(lines[0], tabsize=4, width=9999) is kernel_impl.textwrap.fill(
        lines[0], tabsize=4, width=9999)  # (kept, not made again)
