#!/usr/bin/env python3
"""Prints the bad-input matrix of docs/reliability.md as a Markdown table, from the XML report of
   build/tests/fluorosim_tests --gtest_filter='Matrix/BadInput.*' --gtest_output=xml:matrix.xml
Usage: python3 scripts/reliability-table.py matrix.xml"""
import sys
import xml.etree.ElementTree as ET


def cell(text, limit):
    text = text.replace("|", "\\|").replace("\n", " ").strip()
    return text if len(text) <= limit else text[: limit - 3] + "..."


def main(path):
    rows = []
    for case in ET.parse(path).iter("testcase"):
        props = {p.get("name"): p.get("value") for p in case.iter("property")}
        if "input" not in props:
            continue
        folder = props.get("folder", "")
        name = case.get("name").split("/")[-1]
        command = props.get("command", "").replace(folder, "DIR")
        message = props.get("message", "").replace(folder, "DIR").strip()
        passed = case.find("failure") is None
        rows.append((props["input"], name, command, props.get("exit_code", "?"), props.get("peak_rss_mib", "?"), message, passed))
    print("| # | input | case | command | exit | peak MiB | message |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for i, (kind, name, command, code, rss, message, passed) in enumerate(rows, 1):
        flag = "" if passed else " **(failed)**"
        print(f"| {i} | {kind} | `{name}`{flag} | `{cell(command, 110)}` | {code} | {rss} | {cell(message, 300)} |")


if __name__ == "__main__":
    main(sys.argv[1])
