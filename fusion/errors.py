"""The exception tree. Every error fusion raises on purpose is a FusionError.

FusionError
├── InputError                 bad input from a caller or the wire (ValueError too)
│   ├── ShapeError             wrong dimension or shape
│   ├── NonFiniteError         NaN or inf in an array
│   ├── NotPositiveDefiniteError   a covariance that is not symmetric positive definite
│   ├── TimeError              a time step that goes backwards (negative dt)
│   └── MessageError           bytes from the wire that are not the message expected
│       ├── MalformedMessageError   they do not decode (truncated, not msgpack/JSON, bad UTF-8)
│       ├── InvalidMessageError     they decode but break the schema (the field is named)
│       │   └── UnsupportedVersionError   a schema version this build does not read
├── NumericalError             a computation produced a non-PD covariance (ArithmeticError too)
└── ConfigError                a configuration that cannot work (ValueError too)
"""

from __future__ import annotations


class FusionError(Exception):
    """Base of every error fusion raises on purpose."""


class InputError(FusionError, ValueError):
    """Input that fusion refuses, with the reason in the message."""


class ShapeError(InputError):
    """An array has the wrong shape or dimension."""


class NonFiniteError(InputError):
    """An array holds NaN or infinity."""


class NotPositiveDefiniteError(InputError):
    """A covariance that should be symmetric positive definite is not."""


class TimeError(InputError):
    """A time step goes backwards; rewinding is the tracker's job, never the filter's."""


class NumericalError(FusionError, ArithmeticError):
    """A computation produced a covariance that is not positive definite."""


class ConfigError(FusionError, ValueError):
    """A configuration that cannot work."""


class MessageError(InputError):
    """Bytes from the wire that are not the message expected; the text says why."""


class MalformedMessageError(MessageError):
    """Bytes that do not decode at all."""


class InvalidMessageError(MessageError):
    """A message that decodes but breaks the schema; the text names the field."""


class UnsupportedVersionError(InvalidMessageError):
    """A message of a schema version this build does not read."""
