#!/usr/bin/env python3
"""Checks the built guide (mdBook's HTML) for broken internal links: every relative href and
src must name a file of the book, and every #fragment an id on its page. mdBook itself checks
neither. The README's links into the guide (docs/src/*.md#anchor) are checked against the
built pages too. Usage: book-links.py docs/book [README.md]"""
import re
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

# print.html repeats every page (with its links rewritten into the one page) and 404.html
# links from the site root: neither is a page a reader follows links on.
SKIP = {"print.html", "404.html"}


class Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids, self.refs = set(), []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(a[key])
        for key in ("href", "src"):
            if a.get(key) is not None:
                self.refs.append((tag, key, a[key], self.getpos()[0]))


def main(book: Path, readme) -> int:
    if not (book / "index.html").is_file():
        print(f"book-links: no built book in {book}")
        return 1
    pages = {}
    for f in sorted(book.rglob("*.html")):
        p = Page()
        p.feed(f.read_text(encoding="utf-8"))
        pages[f.resolve()] = p
    bad, checked = [], 0
    for f, p in pages.items():
        rel_f = f.relative_to(book.resolve())
        if rel_f.name in SKIP:
            continue
        for tag, key, ref, line in p.refs:
            u = urlsplit(ref)
            if u.scheme or u.netloc or ref.startswith(("/", "javascript:")):
                continue
            checked += 1
            target = f if not u.path else (f.parent / unquote(u.path)).resolve()
            where = f"{rel_f}:{line}: <{tag} {key}=\"{ref}\">"
            if not target.exists():
                bad.append(f"{where}: no file {target.relative_to(book.resolve()) if target.is_relative_to(book.resolve()) else target}")
                continue
            if target.is_dir():
                target = target / "index.html"
            frag = unquote(u.fragment)
            if frag and target.suffix == ".html":
                ids = pages.get(target.resolve())
                if ids is None or frag not in ids.ids:
                    bad.append(f"{where}: no id \"{frag}\" in {target.relative_to(book.resolve())}")
    if readme is not None:
        src = (book / ".." / "src").resolve()
        text = readme.read_text(encoding="utf-8")
        for m in re.finditer(r"\]\(([^)\s]+)\)", text):
            u = urlsplit(m.group(1))
            if u.scheme or u.netloc or not u.path:
                continue
            checked += 1
            line = text.count("\n", 0, m.start()) + 1
            where = f"{readme.name}:{line}: ({m.group(1)})"
            target = (readme.parent / unquote(u.path)).resolve()
            if not target.exists():
                bad.append(f"{where}: no file {u.path}")
            elif target.suffix == ".md" and target.is_relative_to(src):
                page = (book / target.relative_to(src)).with_suffix(".html").resolve()
                if page not in pages:
                    bad.append(f"{where}: {u.path} is not a page of the book (SUMMARY.md)")
                elif u.fragment and unquote(u.fragment) not in pages[page].ids:
                    bad.append(f"{where}: no id \"{u.fragment}\" in {page.name}")
    for b in bad:
        print(b)
    print(f"book-links: {checked} internal links and images checked in {len(pages)} pages, {len(bad)} broken")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/book"),
                  Path(sys.argv[2]) if len(sys.argv) > 2 else None))
