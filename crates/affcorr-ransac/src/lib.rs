//! Robust estimation (DESIGN.md §5). Empty for now: the engine lands with issue #4.
