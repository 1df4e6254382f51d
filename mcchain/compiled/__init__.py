"""The compiled kernels: where they are cached, compiling them ahead, a first run interpreted."""
