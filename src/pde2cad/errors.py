"""The exception hierarchy of pde2cad.

Every error derives from :class:`Pde2CadError` and from the built-in exception a caller
would naturally catch (the pattern ezdxf uses), so ``except ValueError`` still works.
Messages name the problem and the fix.
"""

from __future__ import annotations


class Pde2CadError(Exception):
    """Base class of every error raised by pde2cad."""


class InputError(Pde2CadError, ValueError):
    """Bad input: missing or unreadable file, wrong format, NaN, nonsense parameters."""


class FitError(Pde2CadError, RuntimeError):
    """A fit could not be computed (degenerate data, too few points for the unknowns)."""


class ExportError(Pde2CadError, OSError):
    """Writing an output file failed."""
