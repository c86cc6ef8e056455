"""Fitting: the weights in the fusion and verify matchers' files, learned on train splits, and the verifier's report.

``fusion`` fits a logistic regression on component matchers' cached frame scores, ``verifier``
one on the cached signals of candidate regions (``logistic`` is the regression both solve);
``verifier_report`` is the verifier's ablation and how far one sigma carries. The matchers
only read the files written here; nothing here trains a network (that is ``pin_match.training``).
"""
