"""Statistics of the studies: tests, the study analyses, the report, power before a study.

Long-format pandas in, tidy DataFrame out (in the manner of pingouin); every test names the
library function that does its work (scipy.stats, statsmodels, pingouin).

- :mod:`~realpen.stats.results` — the one shape of every result (the columns of
  ``results.csv``);
- :mod:`~realpen.stats.nonparametric` — Friedman (tie-corrected, Kendall's W), Wilcoxon
  signed-rank with named p-value methods (``exact``, ``r``, ``spss``), the aligned rank
  transform;
- :mod:`~realpen.stats.anova` — repeated-measures ANOVA (Mauchly, Greenhouse–Geisser and
  Huynh–Feldt, generalised eta squared) and paired pairwise tests (Bonferroni, Holm);
- :mod:`~realpen.stats.intervals` — t and bootstrap confidence intervals;
- :mod:`~realpen.stats.data` — reading and checking a trials CSV, a design's outcomes, each
  participant's cell values;
- :mod:`~realpen.stats.analyses` — the analyses of a design (study 1, study 2, any other),
  with the paper's own choices beside them (``paper_compatible``);
- :mod:`~realpen.stats.paper`, :mod:`~realpen.stats.texts` — the paper's numbers, the
  methods paragraphs;
- :mod:`~realpen.stats.report`, :mod:`~realpen.stats.outputs` — ``report.html`` and the
  report folder;
- :mod:`~realpen.stats.simulate`, :mod:`~realpen.stats.power` — simulated participants and
  power.

Figures: :mod:`realpen.display.study_figures`. May import: :mod:`realpen.study`,
:mod:`realpen.display`, :mod:`realpen.io`, :mod:`realpen.errors`; never :mod:`realpen.live`
or :mod:`realpen.cli`. Importing this package imports none of its modules.
"""
