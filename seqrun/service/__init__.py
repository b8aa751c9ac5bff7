"""The service layer: what owns an arm's bus, and how other processes reach its owner."""
