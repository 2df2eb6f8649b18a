//! Test support for chiaro: approximate comparisons, image diffs, analytic scenes.
