"""Statistics of the studies: tests, the study analyses, the report, power before a study.

Long-format pandas in, tidy DataFrame out (in the manner of pingouin); every test names the
library function that does its work (scipy.stats, statsmodels, pingouin).

- :mod:`~realpen.stats.results` — the one shape of every result (the columns of
  ``results.csv``);
- :mod:`~realpen.stats.long` — checking a long-format table and shaping it into subjects ×
  cells (shared by every test);
- :mod:`~realpen.stats.contrasts` — a design's effects; each effect's F, sums of squares and
  sphericity from orthonormal contrasts, for many tables at once (and statsmodels' F);
- :mod:`~realpen.stats.nonparametric` — Friedman (tie-corrected, Kendall's W), Wilcoxon
  signed-rank with named p-value methods (``exact``, ``r``, ``spss``);
- :mod:`~realpen.stats.anova` — repeated-measures ANOVA (Mauchly, Greenhouse–Geisser and
  Huynh–Feldt, generalised eta squared) and paired pairwise tests (Bonferroni, Holm);
- :mod:`~realpen.stats.art` — the aligned rank transform for factorial designs;
- :mod:`~realpen.stats.intervals` — t and bootstrap confidence intervals;
- :mod:`~realpen.stats.data` — reading and checking a trials CSV, a design's outcomes, each
  participant's cell values;
- :mod:`~realpen.stats.chance` — recognition against chance (each participant's proportion
  correct, and the pooled trials);
- :mod:`~realpen.stats.trial_models` — trial-level models beside the participant-level tests
  (a binomial GEE for recognition, a linear mixed model for log response times);
- :mod:`~realpen.stats.analyses` — the analyses of a design (study 1, study 2, any other),
  with the paper's own choices beside them (``paper_compatible``);
- :mod:`~realpen.stats.paper`, :mod:`~realpen.stats.texts` — the paper's numbers, the
  methods paragraphs;
- :mod:`~realpen.stats.figure_data`, :mod:`~realpen.stats.figures`,
  :mod:`~realpen.stats.power_plot`, :mod:`~realpen.stats.figure_plan` — the study figures:
  the analysis's tables shaped for drawing, the figures, the power plot, and which figures an
  analysis gets with their captions and files (drawn with :mod:`realpen.display.charts`);
- :mod:`~realpen.stats.report`, :mod:`~realpen.stats.outputs` — ``report.html`` and the
  report folder;
- :mod:`~realpen.stats.simulate`, :mod:`~realpen.stats.power` — simulated participants and
  power.

Inside the package the tests build upwards, without cycles: ``long`` and ``contrasts`` →
``nonparametric`` → ``anova`` → ``art``; ``figure_data`` → ``figures`` / ``power_plot`` →
``figure_plan`` → ``report``.

May import: :mod:`realpen.study`, :mod:`realpen.display`, :mod:`realpen.tactile` (a design's
tactile conditions), :mod:`realpen.io`, :mod:`realpen.errors`; never :mod:`realpen.live`
or :mod:`realpen.cli`. Importing this package imports none of its modules.
"""
