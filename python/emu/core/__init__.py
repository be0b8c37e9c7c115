"""Numerics and data with no notion of a scene: mesh geometry and checks,
activation curves, rigid poses, fibre fields, the machine (threads, BLAS).

This package imports nothing itself: blas_kernel runs before the C++ core loads."""
