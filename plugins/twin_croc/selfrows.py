"""croc's self rows: the shared module `twin_nmpc.selfrows` (nmpc keeps the arm from itself with the same pairs and
margins), re-exported here under the name croc's modules use."""

from twin_nmpc.selfrows import SelfRows, link_groups, pair_gaps, self_pairs, self_rows, self_violation

__all__ = ["SelfRows", "link_groups", "pair_gaps", "self_pairs", "self_rows", "self_violation"]
