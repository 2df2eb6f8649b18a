//! The chiaro facade: every technique behind one render() entry point, and compare().
