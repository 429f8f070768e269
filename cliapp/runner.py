"""Running this project's Hydra apps (``tactile-run``, ``tactile-analyze``, ``tactile-import``).

:func:`run_app` puts the config guard (:mod:`cliapp.config_guard`) in front of Hydra and
turns what Hydra or the guard refuses into one line and exit status 2, and a stray Ctrl-C or
SIGTERM into one line and exit status 3. A Ctrl-C whose ``KeyboardInterrupt`` Python drops
because it was raised in a finaliser (a weakref callback, ``__del__``: "Exception ignored",
a traceback, and the program goes on) is delivered again (:func:`redeliver_dropped_interrupt`).
Once a signal has been received, any other error a finaliser drops (an object the
interrupt left half-built, such as a ``zipfile.ZipFile`` cut inside its ``__init__``) goes
to the log at debug level, not to the console: the one line that says what was
interrupted stays the only one.
"""

from __future__ import annotations

import _thread
import atexit
import gc
import logging
import os
import re
import signal
import sys
import threading
import traceback

from omegaconf.errors import ConfigAttributeError, ConfigKeyError, OmegaConfBaseException, ValidationError

from tactile_flow.runstore.status import ExitCode
from tactile_flow.validation import ConfigError, suggest, unknown_key

from .config_guard import install, origin
from .startup import end_at_once

BAD_INPUT, INTERRUPTED = ExitCode.BAD_INPUT, ExitCode.INTERRUPTED
_signals = {"received": 0}      # SIGINT and SIGTERM received by this process (note_signal)


def run_app(app, argv=None, step_fields=None) -> None:
    """Run a ``@hydra.main`` app behind the guard: a config the guard or Hydra refuses (an
    unknown key, bad YAML, a protocol setting ``hydra.*``...) is one line on stderr naming
    it and exit status 2; ``verbose=true`` on the command line adds the traceback. SIGTERM
    is Ctrl-C (the apps' jobs own both while they write); one outside a job ends the
    process with one line and exit status 3, and so does any error escaping the app after
    one (the interrupt cut a library's code short); once the app is done, both are ignored.
    ``step_fields(kind)``: the parameters of a step kind (or None), for the "did you mean" of
    a misspelt step key (``cliapp`` stands below ``protocols`` and cannot ask it)."""
    argv = sys.argv[1:] if argv is None else argv
    os.environ["HYDRA_FULL_ERROR"] = "1"         # Hydra raises instead of printing several lines
    _signals["received"] = 0
    for s, default in ((signal.SIGINT, signal.default_int_handler), (signal.SIGTERM, signal.SIG_DFL)):
        if signal.getsignal(s) in (default, end_at_once):   # left alone: SIGINT ignored (in the background)
            signal.signal(s, _interrupt)
    hook_before, sys.unraisablehook = sys.unraisablehook, _unraisable(sys.unraisablehook)
    code = None         # exit once the exception is gone: the objects its traceback held are freed under our hook
    try:
        install(argv)
        app()
    except (Exception, KeyboardInterrupt) as exc:
        if isinstance(exc, Exception) and "verbose=true" in argv:
            traceback.print_exception(exc)
        # after a signal, an error is the interrupt too: it cut a library's code short and the
        # cleanup raised something else (seen: omegaconf's "'NoneType' object has no attribute
        # '_invalidate_flags_cache'" for a Ctrl-C while Hydra composed the config)
        if isinstance(exc, KeyboardInterrupt) or signals_received():
            print("interrupted", file=sys.stderr)
            code = INTERRUPTED
        else:
            print(f"error: {error_line(exc, step_fields)}", file=sys.stderr)
            code = BAD_INPUT
    finally:
        for s in (signal.SIGINT, signal.SIGTERM):   # the app is done: a late signal must not turn
            signal.signal(s, signal.SIG_IGN)        # its exit status into a kill (at interpreter exit)
        if signals_received():
            gc.collect()                            # what an interrupt left in reference cycles, under our hook
        sys.unraisablehook = hook_before
        # At interpreter exit, after the other atexit handlers (logging's flush...), everything
        # left is frozen: the collections of the exit then skip it (0.3-0.8 s of a dry run's
        # exit otherwise). At exit only: a caller that goes on (a test) keeps its collector.
        atexit.unregister(gc.freeze)
        atexit.register(gc.freeze)
    if code is not None:
        sys.exit(code)


def redeliver_dropped_interrupt(unraisable) -> bool:
    """If ``unraisable`` (a :data:`sys.unraisablehook` argument) is a ``KeyboardInterrupt`` a
    finaliser dropped on the main thread, deliver it again 10 ms later, as SIGINT or (SIGINT
    ignored, as in a program started in the background) SIGTERM, and return True. (Later, so
    that the handler does not run inside this hook, which would drop it again; should it land
    in a finaliser once more, it is delivered once more.)"""
    if not issubclass(unraisable.exc_type, KeyboardInterrupt) or threading.current_thread() is not threading.main_thread():
        return False
    handled = [s for s in (signal.SIGINT, signal.SIGTERM) if callable(signal.getsignal(s))]
    if not handled:
        return False
    later = threading.Timer(0.01, _thread.interrupt_main, args=(handled[0],))
    later.daemon = True
    later.start()
    return True


def signals_received() -> int:
    """How many SIGINT and SIGTERM have come since :func:`run_app` started."""
    return _signals["received"]


def note_signal() -> None:
    """Count a SIGINT or SIGTERM (for a handler installed in place of :func:`run_app`'s)."""
    _signals["received"] += 1


def _interrupt(signum, frame) -> None:
    note_signal()
    raise KeyboardInterrupt


def _unraisable(before):
    def hook(unraisable):
        if redeliver_dropped_interrupt(unraisable):
            return
        if signals_received():
            logging.getLogger(__name__).debug(
                "after an interrupt, a finaliser dropped %s: %s (%r)", unraisable.exc_type.__name__,
                unraisable.exc_value, unraisable.object,
                exc_info=(unraisable.exc_type, unraisable.exc_value, unraisable.exc_traceback))
        else:
            before(unraisable)
    return hook


def report(exc: BaseException, what: str, verbose: bool = False) -> str:
    """An error on stderr as one line, ``what: message`` (the traceback before it with
    ``verbose``); returns the line."""
    if verbose:
        traceback.print_exception(exc)
    located = as_config_error(exc) is not None          # a config key: with the file and line it came from
    line = f"{what}: {error_line(exc) if located else exc}"
    print(line, file=sys.stderr)
    return line


#: omegaconf's names of the types a value could not be converted to, as our messages say them
_EXPECTED = {"Float": "a number", "Integer": "a whole number", "Boolean": "true or false", "String": "a string"}


def error_line(exc: BaseException, step_fields=None) -> str:
    """An exception and its cause as one line (Hydra's messages span several). An error about
    a config key is ``key: what was wrong; what was expected``, the same whether Hydra refused
    it while composing or the run's checks did, and whether the key came from the command
    line or from a file; one written in a data file is prefixed with the file and the line
    (:func:`cliapp.config_guard.origin`). An unknown key is named with the nearest known key,
    in place of Hydra's hint to add it with ``+`` (which the run's checks would refuse)."""
    config_error = as_config_error(exc, step_fields)
    if config_error is not None:
        where = origin(config_error.key)
        return (f"{where[0]} line {where[1]}: " if where else "") + str(config_error)
    missing = re.search(r"Could not find '([\w/]+)/([^']+)'", str(exc))
    if missing:                                   # a group option that does not exist
        group, name = missing.groups()
        listed = str(exc).split("Available options in", 1)[-1].split("Config search path", 1)[0]
        options = [w.strip() for w in listed.splitlines()[1:] if w.strip()] if "Available" in str(exc) else []
        near = suggest(name, options)
        return (f"{group.replace('/', '.')}={name}: no such {group.split('/')[-1]}"
                + (f"; expected one of {', '.join(options)}" if options else "")
                + (f"; did you mean `{near}`?" if near else ""))
    parts = [str(exc)]
    cause = exc.__cause__
    if cause is not None and str(cause) not in parts[0] and type(cause).__name__ != "_RemoteTraceback":
        parts.append(str(cause))                     # (a worker process's traceback is not a message)
    return "; ".join(line.strip() for part in parts for line in part.splitlines() if line.strip())


def as_config_error(exc: BaseException, step_fields=None) -> ConfigError | None:
    """``exc`` as a :class:`validation.ConfigError` naming the key, if it is one or Hydra's or
    omegaconf's refusal of a key (an unknown key, a value of the wrong type), else None."""
    if isinstance(exc, ConfigError):
        return exc
    cause = _omegaconf_cause(exc)
    if cause is None or not isinstance(getattr(cause, "full_key", None), str) or not cause.full_key:
        return None
    full_key = cause.full_key
    if isinstance(cause, (ConfigKeyError, ConfigAttributeError)) and isinstance(cause.key, str) \
            and cause.parent_node is not None:
        parent = full_key[:-len(cause.key)].rstrip(".")
        known = _known_keys(parent, cause.parent_node.keys(), step_fields)
        if parent == "hydra.launcher" and known == ["_target_"]:
            return ConfigError(full_key, "Hydra's default launcher runs the jobs one after another and has no "
                                         "settings; for jobs in parallel add hydra/launcher=joblib (simulated lab "
                                         "only)")
        return unknown_key(parent, cause.key, known)
    converted = re.search(r"Value '(.*)' of type '\w+' could not be converted to (\w+)", str(cause.msg or ""))
    if converted:
        expected = _EXPECTED.get(converted.group(2), converted.group(2))
        return ConfigError(full_key, f"got {converted.group(1)!r}; expected {expected}")
    if isinstance(cause, ValidationError):
        return ConfigError(full_key, " ".join(str(cause.msg or cause).split()))
    return None


def _omegaconf_cause(exc: BaseException):
    """The first omegaconf error in ``exc``'s chain of causes and contexts (Hydra wraps them)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OmegaConfBaseException):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


def _known_keys(parent: str, composed, step_fields=None) -> list[str]:
    """The keys a node may have: a step's parameters for ``...steps[i].<kind>`` (when
    ``step_fields`` knows the kind), else the keys the composed node has."""
    step = re.search(r"steps\[\d+\]\.(\w+)$", parent)
    known = step_fields(step.group(1)) if step and step_fields is not None else None
    return list(known) if known is not None else list(composed)
