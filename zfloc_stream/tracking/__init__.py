"""The filter bank over Sim(2) alignments (filter_bank) and the named rules that decide
births, confirmations, collapses, losses, ambiguity and the reported mode (policy)."""
