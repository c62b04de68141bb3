"""results.print_table: a long string value (the where-lists of the competition experiment) is shortened in
the printed table, and only there."""
from robotatfactory.results import MAX_SHOWN, flat, print_table


def test_long_strings_are_shortened_in_the_table_only(capsys):
    long = "; ".join(f"wall at t {t} s" for t in range(100))
    res = {"where": long, "n_m": 0.25}
    print_table("t", res)
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("where"))
    assert len(row) < MAX_SHOWN + 20 and f"({len(long)} chars)" in row
    assert flat(res)["where"] == long
