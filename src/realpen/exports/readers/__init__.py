"""Readers of the haptic formats RealPen exports: each turns a parsed document into a
:class:`~realpen.exports.readers.fields.Playback`, what a player would play.

One module per format (:mod:`.hjif`, :mod:`.haptic`, :mod:`.ahap`, :mod:`.android`), each with
``read(document, source) -> Playback``; :mod:`.fields` holds the one-line checks they share and
:mod:`.carrier` the envelope-to-vibration model of the envelope formats. Use them through
:func:`realpen.exports.reading.load_haptic`.
"""

__all__: list[str] = []
