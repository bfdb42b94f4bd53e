"""Process support: ordered thread pools (threads), the compiled kernels' set-up
(numba_support), torch's guarded import (torch_support), heap trimming (heap), seeded
generators (rng), machine-independent ranking keys (ties)."""
