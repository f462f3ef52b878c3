#!/usr/bin/python3
"""Writes the libFuzzer dictionaries tests/fuzz/<harness>.dict (tests/fuzz/README.md) from the
readers' own sources: every key a YAML reader knows (its expect_map lists, require/number_or and
map["key"] lookups), the words it compares values with, and each format's syntax. Run from the
repository root when a reader learns a key; the output is committed."""
import re

YAML_SYNTAX = [": ", "- ", "[", "]", "{", "}", ", ", "\n", "\n  ", "#", "'", '"', "~", "null",
               "true", "false", ".inf", "-.inf", ".nan", "0x", "1e308", "-0", "&a ", "*a", "!!str ",
               "? ", "|\n", ">\n", "---\n", "..."]
NPY = ["\x93NUMPY\x01\x00", "{'descr': '", "'fortran_order': False, ", "'fortran_order': True, ",
       "'shape': (", ",), }", "<f4", "<f8", "<i8", "|u1", ">i4", "<c16", "<U8", "<M8[ns]", "|b1"]

READERS = {
    "fuzz_recipe": ["src/io/recipe.cpp"],
    "fuzz_certificate": ["src/io/certificate.cpp"],
    "fuzz_calibration": ["src/calib/calibration.cpp", "src/calib/sensor.cpp"],
    "fuzz_artifact": ["src/calib/artifact.cpp"],
    "fuzz_daemon_config": ["src/cell/config.cpp", "src/cell/plc_sections.cpp"],
    "fuzz_recording": ["src/io/recording_io.cpp"],
}


def yaml_words(files):
    keys, values = set(), set()
    for f in files:
        s = open(f).read()
        for m in re.finditer(r'expect_map\([^;]*?\{([^}]*)\}', s, re.S):
            keys.update(re.findall(r'"([A-Za-z_0-9]+)"', m.group(1)))
        keys.update(re.findall(
            r'(?:require|number_or|integer_in|positive)\([^;]*?"([a-z_0-9]+)"', s))
        keys.update(re.findall(r'\[\s*"([a-z_0-9]+)"\s*\]', s))
        values.update(re.findall(r'[!=]= "([^"\\]{1,40})"', s))
    return sorted(keys), sorted(values - keys)


def json_words(files):
    words = set()
    for f in files:
        s = open(f).read()
        words.update(re.findall(r'(?:at|value|find|contains)\("([a-z_0-9]+)"', s))
    return sorted(words)


def escape(token):
    out = ""
    for ch in token.encode("latin-1"):
        c = chr(ch)
        out += c if 32 <= ch < 127 and c not in '"\\' else "\\x%02x" % ch
    return '"' + out + '"'


def write(harness, tokens):
    with open("tests/fuzz/%s.dict" % harness, "w") as f:
        f.write("# made by tests/fuzz/make_dicts.py from the reader's sources\n")
        for t in dict.fromkeys(tokens):
            f.write(escape(t) + "\n")


for harness, files in READERS.items():
    keys, values = yaml_words(files)
    tokens = [k + ": " for k in keys] + values + YAML_SYNTAX
    if harness == "fuzz_recording":
        tokens += NPY + ["\n%%hotgauge%%\n", "hotgauge-recording/1", "calibration"]
    write(harness, tokens)
write("fuzz_npy", NPY + ["(", ")", ",", " ", "L", "0", "18446744073709551615", "True", "False"])
write("fuzz_results",
      ['"%s": ' % w for w in json_words(["src/results/read_back.cpp"])] +
      ["{", "}", "[", "]", ",", "null", "true", "false", "1e400", "-0", "\"\\u0000\"", "\n",
       '"OK"', '"NOK"', '"DEGRADED"', '"NOT_MEASURED"'])
