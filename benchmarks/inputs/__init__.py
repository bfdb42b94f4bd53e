"""Inputs the benchmarks and the tests both build (one copy): scenes, frames, sessions,
hostile plans and settings, toy networks."""
