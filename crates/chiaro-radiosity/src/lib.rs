//! Radiosity for chiaro: patches, form factors, solvers, view-independent solutions.
