"""Training algorithms, each a set of pure per-seed functions the trainer vmaps and scans."""
