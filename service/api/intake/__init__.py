"""Upload -> one typed checked input, parsed once in a killable process."""
