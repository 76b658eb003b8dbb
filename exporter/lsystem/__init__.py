"""L-system engine: grammar files, safe expressions, parallel rewriting."""

from .derive import Derivation, Limits, derive, derive_many, format_modules
from .grammar import Grammar, GrammarWarning, Module, load_grammar, parse_grammar

__all__ = ["Derivation", "Grammar", "GrammarWarning", "Limits", "Module", "derive", "derive_many",
           "format_modules", "load_grammar", "parse_grammar"]
