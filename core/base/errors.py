"""Exceptions whose messages are written for the person using SceneFit."""


class SceneFitError(Exception):
    """Base class: the message says what went wrong and how to fix it."""


class InputError(SceneFitError):
    """The asset, photo, placement or an option given by the user cannot be used."""

    field: str | None = None   # the setting refused, where one is (a jobs file names its key)


class ModelMissingError(SceneFitError):
    """Model weights were not found where they were looked for."""


class RendererUnavailableError(SceneFitError):
    """Mitsuba (or the LLVM/CUDA backend it needs) cannot be started."""


class Cancelled(SceneFitError):
    """The user cancelled a running job; work done so far is kept."""


class PromptServiceError(SceneFitError):
    """The language model that writes prompts timed out, refused, or answered with an error."""


def check_choice(name: str, value, choices) -> None:
    """A `*_type` setting must be one of its choices: one sentence naming them when it is not."""
    if value not in choices:
        raise InputError(f"{name} must be one of {', '.join(map(str, choices))}, got {value!r}.")
