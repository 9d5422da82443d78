"""What the explorer shows, as its URL says it: a scenario, a law of its lineup and `--set` assignments
(`?scenario=example-6.3.1&law=pd&set=controller.Kv=20&set=simulation.control_period=0.002`), the figures hidden
(`hide=abs_e,V`) and the lecture fonts, so that a link reproduces a view. A URL never names code: an assignment that
names a user kind (`"module:Class"`) is refused."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any
from urllib.parse import quote

from ..studies.scenarios.loader import parse_value
from ..validation import ConfigError

#: the page's figures by name, in their order, with the label of the button that shows or hides each
FIGURES = {"e": "e", "abs_e": "|e| (log)", "phi": "φ̂", "tau": "τ", "V": "V"}

#: characters left as they are in the URL's values: `set=controller.Kv=20`, `set=controller.Kv=[5,50]` stay readable
SAFE = "=.,[]_-"


def key_of(assignment: str) -> str:
    """The dotted key of a `section.key=value` assignment."""
    return assignment.partition("=")[0].strip()


def _names_code(value: Any, key: str) -> bool:
    """Whether a value assigned to `key` holds a user kind: a `kind` that is a "module:Class" string, at any depth."""
    if isinstance(value, dict):
        return any(_names_code(v, k) for k, v in value.items())
    if isinstance(value, list):
        return any(_names_code(v, key) for v in value)
    return key == "kind" and isinstance(value, str) and ":" in value


def refuse_code(assignment: str) -> None:
    """A ConfigError naming the key when `assignment` names a user kind, whose module a scenario imports and runs: the
    explorer takes one only from the scenario file named on its command line, never from a URL."""
    key, _, text = assignment.partition("=")
    if _names_code(parse_value(text.strip()), key.strip().rsplit(".", 1)[-1]):
        raise ConfigError(key.strip(), "names a user kind (\"module:Class\"), which imports and runs code: the explorer "
                          "takes one only from the scenario file named on its command line, never from the URL")


@dataclass(frozen=True)
class View:
    """A scenario (a packaged name, or the command line's file by its name), a lineup entry's name (`law`; None: the
    scenario's own controller), the assignments in order (one per key), whether the fonts are a lecture hall's and the
    names of the figures hidden (:data:`FIGURES`' names)."""

    scenario: str
    law: str | None = None
    sets: tuple[str, ...] = ()
    large: bool = False
    hidden: tuple[str, ...] = ()

    @classmethod
    def of_query(cls, arguments: Mapping[str, Sequence[bytes]], default: str) -> View:
        """The view a request's query arguments (as tornado parses them) ask for; the scenario `default` without one."""

        def text(name: str) -> list[str]:
            return [v.decode("utf-8", "replace") for v in arguments.get(name, ())]

        sets = {key_of(a): a.strip() for a in text("set")}  # one per key, the last given (as --set applies them)
        hidden = {name for value in text("hide") for name in value.split(",")}
        return cls(next(iter(text("scenario")), default) or default, next(iter(text("law")), None) or None,
                   tuple(sets.values()), text("fonts")[-1:] == ["large"], tuple(n for n in FIGURES if n in hidden))

    def checked(self) -> tuple[View, list[ConfigError]]:
        """This view less the assignments that name a user kind, and what :func:`refuse_code` says of each."""
        kept, refused = [], []
        for assignment in self.sets:
            try:
                refuse_code(assignment)
            except ConfigError as exc:
                refused.append(exc)
            else:
                kept.append(assignment)
        return replace(self, sets=tuple(kept)), refused

    def query(self) -> str:
        """The URL's query, `?scenario=…[&law=…][&fonts=large][&hide=…][&set=…]…`."""
        parts = [f"scenario={quote(self.scenario, safe=SAFE)}"]
        if self.law is not None:
            parts.append(f"law={quote(self.law, safe=SAFE)}")
        if self.large:
            parts.append("fonts=large")
        if self.hidden:
            parts.append("hide=" + ",".join(self.hidden))
        parts += [f"set={quote(s, safe=SAFE)}" for s in self.sets]
        return "?" + "&".join(parts)

    def value(self, key: str) -> str | None:
        """The text assigned to `key`, None when the view leaves it as the scenario has it."""
        return next((s.partition("=")[2] for s in self.sets if key_of(s) == key), None)

    def with_set(self, key: str, text: str | None) -> View:
        """This view with `key` assigned `text` (in the place of an earlier assignment of it), or, None or blank, left
        as the scenario has it."""
        sets = [s for s in self.sets if key_of(s) != key]
        if text is not None and text.strip():
            at = next((i for i, s in enumerate(self.sets) if key_of(s) == key), len(sets))
            sets.insert(at, f"{key}={text.strip()}")
        return replace(self, sets=tuple(sets))

    def split(self) -> tuple[list[str], list[str]]:
        """The assignments to the scenario's setting (its arm, plant, trajectory, simulation: what the lineup is built
        on) and those to the controller (applied to the law chosen)."""
        law = [s for s in self.sets if key_of(s).split(".")[0] == "controller"]
        return [s for s in self.sets if s not in law], law
