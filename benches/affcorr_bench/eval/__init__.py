"""The evaluation suite: the paper's experiments on data that can be had offline."""
