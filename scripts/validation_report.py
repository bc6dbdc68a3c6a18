#!/usr/bin/python3
"""Writes docs/validation.md and its charts from duplex_validate's JSON (scripts/validate runs it).

Usage: validation_report.py VALIDATION_JSON OUT_MD CHART_DIR COMMAND LOAD
"""

import json
import math
import os
import sys

INTRO = """# Validation against CIE 171:2006

CIE 171:2006, "Test cases to assess the accuracy of lighting computer programs", defines scenes
whose illuminances are known exactly. These are the cases Duplex can express, each written from
the case's geometry and an exact formula (`tests/validation/CieCases.h`), run by `duplex_validate`
and compared value by value: every cell of a sensor grid against the exact mean illuminance over
that cell, every meter point against the exact illuminance at that point, every face of a room,
every angle of the glass. A value passes when it lies within 4 standard errors plus 0.5% of its
reference (glass: 0.2%). The values of one case share their rays, so their errors are correlated:
a case's mean z^2 varies more between runs than that of independent values would. The short versions of the same cases run
in CTest (`duplex_tests_validation`); this page is their full-length run.

Regenerate (writes this page, `docs/validation/validation.json` and the charts):

```
{command}
```

Measured on a machine shared with other builds (load average {load} when the run ended): the
seconds below are indicative only and must be measured again on a quiet machine.
"""

RECOMPUTED = """## Where the references come from, and which were recomputed

Every reference here is computed from a closed form, not copied from the report's tables:

- **Point source** (inverse-square cosine law): the mean illuminance of a cell is the intensity
  times the cell's solid angle seen from the source, divided by its area (the solid angle of a
  rectangle in closed form). Tables that list the illuminance at the cell's centre differ from
  the cell mean by the curvature of the cosine-cube law over the cell; a Monte Carlo cell
  measures the mean, so the mean is the reference.
- **Area source**: pi L times the exchange area between the cell and the panel, from the
  closed form for parallel rectangles (Howell's catalogue, C-11), over the cell's area; checked in
  CTest against the tabulated 0.19982 of two unit squares 1 apart, its additivity, and the point
  factor integrated over a cell.
- **Area source at points** and **obstruction** (illuminance at points, as the report tabulates
  it): meters at the 64 cell centres read the illuminance at the point by next-event connections,
  against pi L times the closed-form configuration factor from a point to a parallel rectangle
  (area source) and I cos / d^2 outside the obstruction's sharp shadow, 0 inside (obstruction; its
  estimate has no variance, one light and one connection per ray, so it checks the geometry and
  the occlusion exactly). No point lies on the shadow's edge.
- **Black cube**: a closed cube whose faces absorb, the source off its centre: only direct light
  arrives, so each cell's mean is the point-source formula in the face's own frame (the sensors lie
  1 mm inside the faces).
- **Diffuse cubes** (reflectance 0.2 to 0.95): in a closed enclosure of uniform reflectance rho
  with nothing escaping, the flux incident on all the surfaces is exactly Phi / (1 - rho); with the
  source at the cube's centre each face receives a sixth of it. This is exact for the face means,
  not only for a sphere; the report's cube values that use the integrating-sphere approximation
  for the distribution within a face are not used, and no per-cell values are claimed for the
  inter-reflected light.
- **Clear glass**: the exact two-polarisation slab formulas (Fresnel reflectance for s and p at
  each face, the incoherent sum of all internal reflections, Beer-Lambert absorption along the
  refracted path), averaged over s and p for the unpolarised beam. The CIE 171 clear-glass curve
  is a polynomial fit in the cosine of the angle of incidence; it is listed beside each
  transmittance (column "CIE curve") but not used as the reference, because it is a fit to one
  glass: with the absorption chosen so that the slab matches the curve at normal incidence
  (0.8788), the exact slab and the curve still differ by the amounts shown, largest at grazing
  incidence.
- **Daylight** (sky component through unglazed roof and facade openings, direct sun): the report's
  daylight cases 5.9 onward in the form Duplex checks them, with geometry chosen here (a black
  4 m x 4 m x 3 m room, a 2 m x 2 m roof opening or a 2 m x 1.5 m south window, 25 floor points;
  the report's own dimensions and tabulated daylight factors were not reproduced). The reference
  at each point is the zenith luminance times the sky's relative luminance (ISO 15469 / CIE S 011,
  the formulas written out in the validation code apart from the library's sky) times cos cos /
  d^2, integrated over the opening by a 300 x 300 midpoint rule; the zenith luminance is 10,000 lx
  over the sky's horizontal integral by an 800 x 1600 midpoint rule, so the library's own
  integrals and sampling are checked as well. The sun patch is exact: E_n sin(altitude) inside
  the opening's parallel projection, 0 outside.
"""

NOT_MODELLED = """## What Duplex does not model (and the cases left out)

- **Daylight**: the skies have no ground (no externally reflected component) and the sun is a
  parallel beam (no solar disk); glazed openings and the internally reflected component of the
  report's later daylight cases are not run here, and neither are its own room dimensions and
  tables (the cases above use their own geometry).
- **IES-source cases**: Duplex reads LM-63 profiles (goniometric lights), but the report's
  luminaire files and tables are not reproduced here; a point light with an IES table is checked
  against its intensity table by the unit tests (`IesProfileTest`, `SensorPhotometryTest`).
- **Obstructions**: the obstruction case reads points (above); cell means behind
  an obstruction (the shadow boundary clipped against each cell), an area source behind an
  obstruction (the visible part of the panel per point) are not yet written.
- **Per-cell inter-reflected illuminance** in rooms: no closed form exists for a cube's
  distribution within a face; only the face means are exact (above).
- **Walls for the area source** (perpendicular rectangles): not yet written.
- **Coherent effects**: glass is treated incoherently (no thin-film interference), which is what
  the report assumes for 6 mm glass.
- **Polarisation**: carried through smooth dielectrics, mirrors and coatings; diffuse reflection
  and fog scattering depolarise; rough (Gaussian, ABg) lobes keep the specular direction's
  polarisation state, turned to the scattered direction.
"""


def fmt(x, unit):
    if x is None:
        return ""
    if unit == "fraction":
        return f"{x:.5f}"
    return f"{x:.4g}" if abs(x) < 1000 else f"{x:.1f}"


def chart(case, chart_dir):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    rows = case["rows"]
    fig, ax = plt.subplots(figsize=(8, 3.2))
    if case["name"] == "clear-glass":
        for kind, colour in (("T", "tab:blue"), ("R", "tab:red")):
            sel = [r for r in rows if r["label"].startswith(kind + " ")]
            ang = [float(r["label"].split()[2]) for r in sel]
            ax.plot(ang, [r["reference"] for r in sel], "-", color=colour, label=f"{kind} exact (s and p)")
            ax.errorbar(ang, [r["value"] for r in sel], yerr=[4 * r["stderr"] for r in sel], fmt="o", ms=3,
                        color=colour, label=f"{kind} Duplex (4 SE)")
            if kind == "T":
                ax.plot(ang, [r["other"] for r in sel], "--", color="grey", label="T CIE curve")
        ax.set_xlabel("angle of incidence (degrees)")
        ax.set_ylabel("fraction")
    else:
        # Values whose reference is 0 (in a shadow) have no relative error: the table lists them.
        rows = [r for r in rows if r["reference"] != 0]
        x = list(range(len(rows)))
        ax.plot(x, [(r["value"] - r["reference"]) / r["reference"] * 100 for r in rows], "o", ms=3,
                label="Duplex - exact")
        ax.fill_between(x, [-(4 * r["stderr"] / r["reference"] + r["relative_tolerance"]) * 100 for r in rows],
                        [(4 * r["stderr"] / r["reference"] + r["relative_tolerance"]) * 100 for r in rows],
                        color="tab:green", alpha=0.2, label="4 SE + tolerance")
        ax.axhline(0, color="black", lw=0.5)
        ax.set_xlabel("value (in table order, those of reference 0 left out)")
        ax.set_ylabel("error (%)")
    ax.set_title(case["title"], fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = os.path.join(chart_dir, case["name"] + ".png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return os.path.basename(path)


def main():
    src, out_md, chart_dir, command, load = sys.argv[1:6]
    with open(src) as f:
        report = json.load(f)
    cases = report["cases"]
    lines = [INTRO.format(command=command, load=load)]
    lines.append("## Summary\n")
    lines.append("| case | values | pass | mean z^2 | largest abs z | largest error | rays per run | seconds |")
    lines.append("|---|---:|---:|---:|---:|---:|---:|---:|")
    for c in cases:
        rows = c["rows"]
        z2 = sum(r["z"] ** 2 for r in rows) / len(rows)
        zmax = max(abs(r["z"]) for r in rows)
        emax = max(abs(r["value"] - r["reference"]) / abs(r["reference"]) for r in rows if r["reference"] != 0)
        passed = sum(1 for r in rows if r["passes"])
        lines.append(f"| [{c['name']}](#{c['name']}) | {len(rows)} | {passed} | {z2:.2f} | {zmax:.2f} | "
                     f"{emax * 100:.2f}% | {c['rays']:,} | {c['seconds']:.1f} |")
    total = sum(len(c["rows"]) for c in cases)
    passed = sum(1 for c in cases for r in c["rows"] if r["passes"])
    lines.append(f"\n{passed} of {total} values pass (rays scale {report['scale']:g}).\n")
    lines.append(RECOMPUTED)
    for c in cases:
        lines.append(f"## {c['name']}\n")
        lines.append(f"{c['title']}. Reference: {c['reference']}. Unit: {c['unit']}.\n")
        for note in c["notes"]:
            lines.append(f"- {note}")
        if c["notes"]:
            lines.append("")
        png = chart(c, chart_dir)
        if png:
            lines.append(f"![{c['name']}](validation/{png})\n")
        has_other = any(r["other"] is not None for r in c["rows"])
        head = "| value | reference | Duplex | SE | error | z |" + (" CIE curve |" if has_other else "")
        lines.append(head)
        lines.append("|---|---:|---:|---:|---:|---:|" + ("---:|" if has_other else ""))
        for r in c["rows"]:
            err = (r["value"] - r["reference"]) / r["reference"] * 100 if r["reference"] else math.nan
            mark = "" if r["passes"] else " **fails**"
            row = (f"| {r['label']}{mark} | {fmt(r['reference'], c['unit'])} | {fmt(r['value'], c['unit'])} | "
                   f"{fmt(r['stderr'], c['unit'])} | {err:+.2f}% | {r['z']:+.2f} |")
            if has_other:
                row += f" {fmt(r['other'], c['unit'])} |"
            lines.append(row)
        lines.append("")
    lines.append(NOT_MODELLED)
    with open(out_md, "w") as f:
        f.write("\n".join(lines))


if __name__ == "__main__":
    main()
