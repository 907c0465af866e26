"""Cross-cutting helpers: rank-aware logging, MPI utilities, TOML writing."""
