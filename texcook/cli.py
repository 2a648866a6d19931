"""The `texcook` command: parse, call the library, print. Results go to stdout,
errors to stderr as one line; exit 0 ok, 1 a texture failed, 2 usage."""

import functools
import json
import math
import os
import sys
import warnings

import click

from . import __version__, choices
from .container.table import EXTENSION_LIST
from .errors import TexcookError, UsageError, printable

# The file each command works on, named when memory runs out (the library's own
# errors name their file already).
_FILE_ARGS = ("source", "path", "a")


def _fail(message, code):
    click.echo(f"texcook: error: {printable(message)}", err=True)
    sys.exit(code)


def _guarded(fn):
    """Turn library errors into one-line messages and exit codes; --debug shows
    the traceback instead."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        debug = click.get_current_context().find_root().params.get("debug", False)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RuntimeWarning)
                result = fn(*args, **kwargs)
            _numeric_note([w for w in caught if issubclass(w.category, RuntimeWarning)], kwargs)
            return result
        except TexcookError as exc:
            if debug:
                raise
            _fail(str(exc), exc.exit_code)
        except (click.exceptions.Exit, click.ClickException):
            raise
        except KeyboardInterrupt:
            # outputs are renamed into place only when complete: nothing partial is left
            if debug:
                raise
            click.echo("texcook: interrupted", err=True)
            sys.exit(130)
        except MemoryError:
            if debug:
                raise
            name = next((kwargs[k] for k in _FILE_ARGS if kwargs.get(k)), None)
            _fail(f"{name}: out of memory (lower --max-memory to refuse such inputs before reading them)"
                  if name else "out of memory", 1)
        except BrokenPipeError:
            # the reader (head, grep -q) went away: end quietly, as shell tools do
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            sys.exit(141)
        except Exception as exc:  # a bug, not the user's fault: still one line
            if debug:
                raise
            if _interrupted(exc):
                click.echo("texcook: interrupted", err=True)
                sys.exit(130)
            _fail(f"internal error: {type(exc).__name__}: {exc} (run with --debug for details)", 1)

    return wrapper


def _numeric_note(caught, kwargs):
    """numpy's overflow and invalid-value warnings become one line naming the
    file (values far outside what the format or step expects): the terminal
    never shows numpy's own multi-line warnings."""
    if not caught:
        return
    name = next((kwargs[k] for k in _FILE_ARGS if kwargs.get(k)), None)
    where = f"{name}: " if name else ""
    click.echo(f"texcook: note: {printable(where)}numeric overflow or invalid values while processing "
               f"({printable(str(caught[0].message))}); values far outside 0..1 were clamped or lost", err=True)


def _interrupted(exc):
    """Ctrl-C that arrived inside a jitted call surfaces as a SystemError whose
    cause is the KeyboardInterrupt."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _json_value(x):
    """JSON has no Inf or NaN: they are written as the strings "inf", "-inf", "nan"."""
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if isinstance(x, float) and math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, dict):
        return {k: _json_value(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_value(v) for v in x]
    return x


def _print_json(obj):
    click.echo(json.dumps(_json_value(obj), indent=2, allow_nan=False))


def _db(x):
    return f"{x:.2f}" if math.isfinite(x) else str(x)


def _max_memory(ctx, param, value):
    from .fileio import parse_size, set_max_memory

    try:
        # None (not given) restores the default: one process may run several commands
        set_max_memory(None if value is None else parse_size(value))
    except UsageError as exc:
        raise click.BadParameter(str(exc)) from None
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="texcook")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.option("--max-memory", metavar="SIZE", callback=_max_memory, expose_value=False, is_eager=True,
              help="Refuse inputs whose decoded size (texels x channels x 4 bytes) exceeds SIZE, e.g. 2G, 512M "
                   "[default: an eighth of the physical memory, or $TEXCOOK_MAX_MEMORY].")
def cli(debug):
    """Bake source images into GPU-ready KTX2 textures."""


class _SettingType(click.ParamType):
    """What a recipe setting takes, shown in help (its choices, or a number or
    text). Numbers are parsed; nothing is refused here: the recipe checks each
    value once, when it is made, and says what is wrong in one line."""

    def __init__(self, setting):
        self.setting = setting
        self.name = {"int": "integer", "float": "float"}.get(setting.kind, "text")

    def get_metavar(self, param, ctx=None):
        s = self.setting
        return s.metavar or (f"[{'|'.join(s.choices)}]" if s.choices else self.name.upper())

    def shell_complete(self, ctx, param, incomplete):
        from click.shell_completion import CompletionItem

        return [CompletionItem(c) for c in self.setting.choices if c.startswith(incomplete)]

    def convert(self, value, param, ctx):
        parse = {"int": int, "float": float}.get(self.setting.kind)
        if parse is not None and isinstance(value, str):
            try:
                return parse(value)
            except ValueError:
                pass  # the recipe refuses it, naming the setting
        return value


def _setting_help(setting):
    """The setting's help with its default and range, as click shows them."""
    notes = []
    shown = setting.shown
    if shown is None and setting.default not in (None, False):
        shown = setting.flags[0].split("/")[0].lstrip("-") if setting.default is True else setting.default
    if shown is not None:
        notes.append(f"default: {shown}")
    if setting.lo is not None and setting.hi is not None:
        notes.append(f"{setting.lo:g}<=x<={setting.hi:g}")
    return (setting.help + (f"  [{'; '.join(notes)}]" if notes else "")).strip()


def recipe_options(*names):
    """Add recipe settings as options (all that have a flag when none are
    named), each made from its one declaration in recipe.SETTINGS. The command
    gets every value under the setting's flat name, None when not given, so a
    saved recipe's values are overridden only by flags on the command line."""
    from .recipe import SETTINGS

    chosen = [SETTINGS[n] for n in names] if names else [s for s in SETTINGS.values() if s.flags]

    def add(fn):
        for setting in reversed(chosen):  # click lists the options in the order they are added, last first
            if setting.kind == "bool":
                option = click.option(*setting.flags, setting.name, is_flag=True, default=None,
                                      help=_setting_help(setting))
            else:
                option = click.option(*setting.flags, setting.name, type=_SettingType(setting), default=None,
                                      help=_setting_help(setting))
            fn = option(fn)
        return fn

    return add


def _recipe_from(settings, base=None):
    """The recipe the command line's settings make from `base` (default: the
    default recipe): those not given keep base's values."""
    from .recipe import Recipe

    return (base or Recipe()).replace(**{k: v for k, v in settings.items() if v is not None})


def _load_recipe(path):
    """A recipe saved as JSON or TOML (`--save-recipe`, or written by hand)."""
    from .fileio import read_bytes
    from .recipe import Recipe

    raw = read_bytes(path, "recipe")  # a regular file only: a FIFO would block
    try:
        if path.lower().endswith(".toml"):
            import tomllib

            data = tomllib.loads(raw.decode("utf-8"))
        else:
            data = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise UsageError(f"not a readable recipe ({str(exc).splitlines()[0]})", path) from None
    except RecursionError:
        raise UsageError("not a readable recipe (nested too deeply)", path) from None
    try:
        return Recipe.from_dict(data)
    except UsageError as exc:
        raise UsageError(str(exc), path) from None


@cli.command()
@click.argument("source", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help=f"Output {EXTENSION_LIST} file.")
@recipe_options()
@click.option("--threads", type=click.IntRange(min=1), default=None, help="Threads [default: all cores].")
@click.option("--sat", "sat_path", type=click.Path(dir_okay=False), default=None,
              help="Also write a summed-area table of the source to this .ktx2.")
@click.option("--recipe", "recipe_path", type=click.Path(dir_okay=False), default=None,
              help="Start from a recipe saved as .json or .toml; flags given here override it.")
@click.option("--save-recipe", type=click.Path(dir_okay=False), default=None,
              help="Write the recipe used as JSON (to bake the same way again with --recipe).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--plan", "show_plan", is_flag=True,
              help="Print what the bake would do (its plan; with --json as JSON) without reading pixels or "
                   "writing a file.")
@_guarded
def bake(source, output, threads, sat_path, recipe_path, save_recipe, as_json, show_plan, **settings):
    """Bake SOURCE into a texture file."""
    from ._jit import set_first_use_notice
    from .fileio import atomic_write
    from .pipeline import bake_file

    recipe = _recipe_from(settings, None if recipe_path is None else _load_recipe(recipe_path))
    if show_plan:
        from .pipeline import plan_file

        plan = plan_file(source, output, recipe, sat_path)
        if as_json:
            _print_json(plan.to_dict())
        else:
            click.echo(plan.text())
        return
    if save_recipe is not None:
        atomic_write(save_recipe, (json.dumps(recipe.to_dict(), indent=2, sort_keys=True) + "\n").encode())
    if as_json:  # a first-use compile is named in one line, with no live seconds under it
        set_first_use_notice("line")
    summary = bake_file(source, output, recipe, sat_path=sat_path, threads=threads)
    for note in summary["notes"]:
        click.echo(f"texcook: note: {summary['input']}: {note}", err=True)
    if as_json:
        _print_json(summary)
    else:
        why = f" ({summary['colour_space_reason']})" if "colour_space_reason" in summary else ""
        space = summary["colour_space"]
        if summary.get("colour_space_recorded") is False:  # as `info` says of .astc files
            space = f"colour space not recorded (values stored {'sRGB-encoded' if space == 'srgb' else 'linear'})"
        click.echo(
            f"{summary['output']}: {summary['format']} {space}{why} "
            f"{summary['width']}x{summary['height']}, {summary['levels']} level(s), {summary['bytes']} bytes"
            + (f", {summary['clamped']} value(s) clamped to the format's range" if summary.get("clamped") else "")
        )


@cli.command()
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@_guarded
def formats(as_json):
    """List every format with its facts, presets and options."""
    from . import codecs
    from . import formats as table

    available = set(codecs.names())
    rows = []
    for fmt in table.FORMATS.values():
        if fmt.name in available:
            rows.append(codecs.get(fmt.name).facts())
        else:
            rows.append(dict(fmt.facts(), presets=[], options=[], available=False))
    if as_json:
        _print_json(rows)
        return
    click.echo(f"{'format':<11} {'vkFormat':<11} {'block':<6} {'bits/texel':>10} {'channels':>8} {'sample':<7}  "
               "options")
    for row in rows:
        vk = row["vk_format"]
        kind = "" if row["encoder"] else " (stored only: summed-area tables)"
        if row["encoder"] and row.get("available") is False:
            kind = " (not in this build)"
        if row.get("stored_as"):
            kind += f" (written as {row['stored_as']}" + (f" with a recorded {row['transform']} step)"
                                                          if row["transform"] else ")")
        vks = f"{vk['unorm']}/{vk['srgb']}" if vk["srgb"] else f"{vk['unorm']}"
        block = f"{row['block'][0]}x{row['block'][1]}"
        opts = ", ".join(o["name"] for o in row["options"]) or "-"
        click.echo(f"{row['name']:<11} vk {vks:<8} {block:<6} {row['bits_per_texel']:>10.3g} {row['channels']:>8} "
                   f"{row['sample']:<7}  {opts}{kind}")


@cli.command()
@click.argument("path", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@_guarded
def info(path, as_json):
    """Describe a KTX2, DDS or .astc file: format, sizes, levels, colour space, metadata.
    Levels are never decompressed."""
    from .container.table import describe_file

    desc = describe_file(path)  # only the header and metadata are read, however large the file
    if as_json:
        _print_json(desc)
        return
    for key, value in desc.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            click.echo(f"{key}:")
            for row in value:
                click.echo("  " + "  ".join(f"{k}={v}" for k, v in row.items()))
        elif isinstance(value, (list, tuple)):
            click.echo(f"{key}: {'x'.join(str(v) for v in value)}")
        elif isinstance(value, dict):
            click.echo(f"{key}:")
            for k, v in value.items():
                click.echo(f"  {k}: {v}")
        else:
            click.echo(f"{key}: {value}")


@cli.command()
@click.argument("path", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output .png, .exr, .tif...")
@click.option("--level", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--all-levels", is_flag=True, help="Write every level as OUTPUT with _mipN before the extension.")
@_guarded
def decode(path, output, level, all_levels):
    """Decode a KTX2 or DDS file to an image."""
    import numpy as np

    from .fileio import refuse_same_file
    from .image import write_images
    from .pipeline import load_texture

    refuse_same_file(path, output)
    tex = load_texture(path)
    space = "srgb" if tex.srgb else "linear"
    if all_levels:
        stem, ext = os.path.splitext(output)
        items = [(f"{stem}_mip{i}{ext}", px) for i, px in enumerate(tex.levels)]
        for name, _ in items:
            refuse_same_file(path, name)
    elif level >= len(tex.levels):
        raise UsageError(f"level {level} does not exist ({len(tex.levels)} level(s))", path)
    else:
        items = [(output, tex.levels[level])]
    nonfinite = sum(int(np.count_nonzero(~np.isfinite(px))) for _, px in items if px.dtype.kind == "f")
    write_images(items, space)  # all or nothing
    for name, _ in items:
        click.echo(name)
    if nonfinite and os.path.splitext(output)[1].lower() not in (".exr", ".hdr"):
        click.echo(f"texcook: note: {printable(path)}: {nonfinite} NaN or Inf value(s) written as 0 (NaN) "
                   "or clamped (Inf) in this 8/16-bit output; write .exr to keep them", err=True)


def _angles(entry):
    a = entry.get("angular")
    return f", angle mean {a['mean']:.3f} p99 {a['p99']:.3f} max {a['max']:.2f} deg" if a else ""


def _min_psnr(ctx, param, value):
    if value is not None and math.isnan(value):
        raise click.BadParameter("must be a number of dB (or inf), not nan")
    return value


@cli.command()
@click.argument("a", type=click.Path())
@click.argument("b", type=click.Path())
@click.option("--level", type=click.IntRange(min=0), default=None, help="Compare only this level.")
@click.option("--min-psnr", type=float, default=None, callback=_min_psnr,
              help="Exit 1 when any compared level is below this (dB).")
@click.option("--normal-map", is_flag=True,
              help="Also the angle between the normals (X, Y in R, G; Z rebuilt); on already when either file "
                   "is a bake with --normal-map.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@_guarded
def compare(a, b, level, min_psnr, normal_map, as_json):
    """PSNR per channel and level between two images or textures; for normal
    maps also the angle between the normals (mean and 99th percentile, degrees)."""
    from .pipeline import compare as compare_files

    result = compare_files(a, b, level, normal_map)
    worst = min((row["psnr"] for row in result["levels"]), default=math.inf)
    result["passed"] = min_psnr is None or worst >= min_psnr
    if min_psnr is not None:
        result["min_psnr"] = min_psnr
    if as_json:
        _print_json(result)
    else:
        for row in result["levels"]:
            per = " ".join(f"{c}={_db(v)}" for c, v in row["channels"].items())
            odd = f", {row['nonfinite']} NaN/Inf value(s)" if row.get("nonfinite") else ""
            if "log2_psnr" in row:
                odd += f", log2 RGB {_db(row['log2_psnr'])} dB, mPSNR {_db(row['mpsnr'])} dB"
            click.echo(f"level {row['level']} {row['width']}x{row['height']}: {_db(row['psnr'])} dB ({per}){odd}"
                       f"{_angles(row)}")
        click.echo(f"overall: {_db(result['psnr'])} dB{_angles(result)}")
    if not result["passed"]:
        click.echo(f"texcook: PSNR {_db(worst)} dB is below --min-psnr {min_psnr}", err=True)
        sys.exit(1)


@cli.command()
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "outdir", required=True, type=click.Path(file_okay=False),
              help="Folder for the baked textures, scene.json and the rewritten model.")
@click.option("--target", type=click.Choice(choices.SCENE_TARGETS), default="desktop", show_default=True,
              help="desktop: BC formats; mobile: ASTC (ETC2/EAC in a build without ASTC); mobile-etc: ETC2/EAC, "
                   "for OpenGL ES 3 and WebGL devices without ASTC; universal: Basis Universal ETC1S "
                   "(KHR_texture_basisu), transcoded by the viewer for any GPU, near the size of JPEGs.")
@click.option("--container", type=click.Choice(choices.SCENE_CONTAINERS), default=choices.DEFAULT_CONTAINER,
              show_default=True)
@recipe_options("preset", "rdo")
@click.option("--zstd", "zstd", type=click.IntRange(0, choices.ZSTD_LEVELS[1]), default=None, metavar="LEVEL",
              help="Zstandard supercompression of the KTX2 files, 0 for none [default: 19].")
@click.option("--fallback", type=click.Choice(("keep", "drop")), default=None,
              help="Keep the source images in the rewritten model for viewers without the extension, or drop "
                   "them [default: drop for .glb, keep for .gltf].")
@click.option("--keep-going", is_flag=True,
              help="Bake what can be baked; list what cannot, keeping its source image in the model.")
@click.option("--threads", type=click.IntRange(min=1), default=None, help="Threads [default: all cores].")
@click.option("-q", "--quiet", is_flag=True, help="Print only what was not baked, and errors.")
@click.option("--json", "as_json", is_flag=True, help="Print scene.json.")
@_guarded
def scene(model, outdir, target, container, preset, rdo, zstd, fallback, keep_going, threads, quiet, as_json):
    """Bake MODEL's (.gltf or .glb) textures for what its materials use them for."""
    from ._jit import set_first_use_notice
    from .batch import Terminated, sigterm_as_interrupt
    from .scene import bake_scene, summary_line

    checked = _recipe_from({"preset": preset, "rdo": rdo}).codec  # checked before anything is read
    preset = checked.preset
    bar = _SceneBar() if sys.stderr.isatty() and not quiet else None
    set_first_use_notice("off" if quiet else "line")  # the bar is the live line
    try:
        with sigterm_as_interrupt():  # SIGTERM unwinds like Ctrl-C: OUTDIR is left as it was
            report = bake_scene(model, outdir, target=target, container=container, preset=preset,
                                threads=threads, zstd=zstd, fallback=fallback, keep_going=keep_going, progress=bar,
                                rdo=None if rdo is None else checked.rdo)
    except Terminated:
        click.echo("texcook: terminated", err=True)
        sys.exit(143)
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        _print_json(report)
    elif not quiet:
        _scene_lines(report)
    for why, rows in _grouped(report["not_baked"], "why").items():
        uses = _some(f"{r['material_name']} {r['slot']}" for r in rows)
        click.echo(f"texcook: not baked: {uses}: {why}", err=True)
    named = {row["why"] for row in report["not_baked"]}
    for row in report.get("refused", []):
        line = f"{row['what']} ({row['uri']}): {row['why']}" if row["uri"] else f"{row['what']}: {row['why']}"
        if line not in named:
            click.echo(f"texcook: refused: {line}", err=True)
    if not as_json and not quiet:
        click.echo(summary_line(report, outdir))
    if report["not_baked"] or report.get("refused"):
        sys.exit(1)


def _some(items, shown=3):
    """"a, b, c and 7 more"."""
    items = list(dict.fromkeys(items))
    more = f" and {len(items) - shown} more" if len(items) > shown else ""
    return ", ".join(items[:shown]) + more


def _grouped(rows, key):
    out = {}
    for row in rows:
        out.setdefault(row[key], []).append(row)
    return out


def _scene_lines(report):
    """A line per bake with the steps that ran, each step's reason, and each
    note once."""
    by_bake = _grouped(report["textures"], "bake")
    notes = {}
    for bake in report["bakes"]:
        entries = by_bake.get(bake["id"], [])
        textures = [str(e["texture"]) for e in entries]
        uses = _some(f"{u['material_name']} {u['slot']}" for e in entries for u in e["uses"])
        ran = ", ".join(bake["steps"]["ran"]) or "no optional step"
        click.echo(f"{bake['name']}: texture{'s' if len(textures) > 1 else ''} {_some(textures)} ({uses}): "
                   f"{bake['format']} {bake['colour_space']}, {bake['levels']} level(s), {bake['bytes']} bytes, "
                   f"level 0 {_db(bake['psnr'])} dB ({bake['psnr_channels']}); ran {ran}")
        for step, why in bake["steps"]["ran"].items():
            click.echo(f"  {step}: ran, {why}")
        for step, why in bake["steps"]["skipped"].items():
            click.echo(f"  {step}: skipped, {why}")
        for note in bake["notes"]:
            notes.setdefault(note, []).append(bake["name"])
    for note, names in notes.items():
        click.echo(f"texcook: note: {_some(names)}: {note}", err=True)


class _SceneBar:
    """Bakes done, failures and time left on stderr (a terminal only)."""

    def __init__(self):
        self.bar = None
        self.failed = 0

    def __call__(self, index, result, count):
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=count, unit="bake", file=sys.stderr, dynamic_ncols=True, leave=False)
        if index is None:  # before the first bake: the bar shows from the start
            return
        if isinstance(result, Exception):
            self.failed += 1
            self.bar.set_postfix(failed=self.failed, refresh=False)
        self.bar.update(1)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _csv(value):
    return [v.strip() for v in value.split(",") if v.strip()] if value else None


class _BenchBar:
    """bench's rows done and the row under way on stderr (a terminal only),
    shown from the first row on: the first rows compile kernels. Also the
    stream compile notices are written to, above the bar."""

    def __init__(self):
        self.bar = None

    def __call__(self, done, total, label):
        from tqdm import tqdm

        if self.bar is None:
            self.bar = tqdm(total=total, unit="row", file=sys.stderr, dynamic_ncols=True, leave=False)
        self.bar.set_description(label or "done", refresh=False)
        self.bar.update(done - self.bar.n)
        self.bar.refresh()

    def isatty(self):
        return True

    def write(self, text):
        from tqdm import tqdm

        if text.strip():
            tqdm.write(text.rstrip("\n"), file=sys.stderr)

    def flush(self):
        sys.stderr.flush()

    def close(self):
        if self.bar is not None:
            self.bar.close()


@cli.command()
@click.argument("paths", nargs=-1, type=click.Path(exists=True))
@click.option("--formats", "format_list", default=None,
              help="Comma-separated formats, or all [default: bc1,bc1a,bc3,bc4,bc5,etc1].")
@click.option("--presets", "preset_list", default=None, help="Comma-separated presets, or all [default: all].")
@click.option("--peers/--no-peers", default=True, show_default=True, help="Measure the peers installed here.")
@click.option("--threads", type=click.IntRange(min=1), default=None, help="Threads for the all-cores figure.")
@click.option("--repeat", type=click.IntRange(min=1), default=3, show_default=True, help="Best of K runs per image.")
@click.option("--cold", is_flag=True, help="Also time each preset's first call in a fresh process with an empty cache.")
@click.option("--stages", "stages_image", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Instead: seconds per stage of a whole bake of this image.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="Write every figure here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, help="Write the plots as PNG.")
@click.option("--plot-preset", default=choices.DEFAULT_PRESET, show_default=True, help="Preset of the size panel.")
@_guarded
def bench(paths, format_list, preset_list, peers, threads, repeat, cold, stages_image, json_path, plot_path,
          plot_preset):
    """Quality against encode time for every format and preset, with peers
    (default images: the bundled corpus)."""
    from . import bench as harness
    from ._jit import set_first_use_notice
    from .fileio import atomic_write, stage_bytes

    for out in (json_path, plot_path):
        if out is not None:  # a folder that is missing or not writable fails now, not after the run
            stage_bytes(out, b"").discard()
    presets = _csv(preset_list)
    presets = None if presets == ["all"] else presets
    if stages_image:
        result = harness.stages(stages_image, _csv(format_list) or ["bc1"], presets or ["fast"], threads, repeat)
        for row in result["rows"]:
            parts = " ".join(f"{k}={v:.3f}" for k, v in row["seconds"].items())
            click.echo(f"{row['format']} {row['preset']}: {row['total_s']:.3f} s ({parts})")
    else:
        bar = _BenchBar() if sys.stderr.isatty() else None
        set_first_use_notice("line")  # the notices are written above the bar, which is the live line
        try:
            result = harness.run(paths, _csv(format_list), presets, peers, threads, repeat, cold, bar,
                                 notices=bar)
        finally:
            if bar is not None:
                bar.close()
        click.echo(harness.table(result))
        for line in harness.dominated_warnings(result):
            click.echo(line, err=True)
        for fmt, missing in result["missing_peers"].items():
            click.echo(f"texcook: note: peers not installed for {fmt}: {', '.join(missing)}", err=True)
        for fmt, folders in result["unscored"].items():
            click.echo(f"texcook: note: no image to measure {fmt} on: the set has no {' or '.join(folders)} "
                       "folder", err=True)
        if plot_path:
            harness.plot(result, plot_path, plot_preset)
    if json_path:
        atomic_write(json_path, (json.dumps(_json_value(result), indent=1) + "\n").encode())


@cli.command()
@click.argument("format_names", nargs=-1, metavar="[FORMATS|all]")
@click.option("-j", "--processes", type=click.IntRange(min=1), default=None,
              help="Worker processes [default: one per core].")
@_guarded
def prepare(format_names, processes):
    """Compile the kernels of FORMATS (comma- or space-separated; default all)
    ahead of time, so a first bake does not wait for them."""
    from .prepare import BAKE, prepare as compile_ahead

    names = [n for arg in format_names for n in _csv(arg) or []]

    def done(job):
        what = "a bake's colour and mip kernels" if job.module == BAKE else job.module.rsplit(".", 1)[-1]
        if job.beside:
            what += ", beside"
        if job.formats:
            what += f" ({', '.join(job.formats) if len(job.formats) <= 4 else f'{len(job.formats)} formats'})"
        click.echo(f"{what}: {job.seconds:.1f} s (CPU {job.cpu_seconds:.1f} s)")

    def started(jobs, workers):
        codecs = [m.rsplit(".", 1)[-1] for m in jobs if m != BAKE]
        click.echo(f"texcook: compiling the kernels of {', '.join(codecs)} and a bake's own on {workers} "
                   f"process{'es' if workers > 1 else ''}", err=True)

    _, total = compile_ahead(names or None, processes, done, started)
    click.echo(f"total: {total:.1f} s")


@cli.command()
@click.argument("texture", type=click.Path(dir_okay=False))
@click.option("--scene", default=None,
              help="plane (grazing angle), tunnel or quad [default: plane; quad for an alpha-tested texture, "
                   "so that the cut-out's edge is in view].")
@click.option("--filter", "filter_name", default=None,
              help="nearest, bilinear, trilinear, aniso[N], ewa, sat or all [default: the sampler's in a scene.json "
                   "beside the texture, else trilinear].")
@click.option("--size", default="512x512", show_default=True, help="Frame size WxH.")
@click.option("--wrap", default=None, help="repeat, clamp or mirror; S,T for each axis [default: the sampler's, else repeat].")
@click.option("--alpha-cutoff", type=float, default=None, help="Alpha-test at this cutoff [default: the texture's, if any].")
@click.option("--reference", is_flag=True, help="Render the supersampled reference and measure each filter against it.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None, help="Write the image here (PNG).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@_guarded
def preview(texture, scene, filter_name, size, wrap, alpha_cutoff, reference, output, as_json):
    """Show TEXTURE on a surface as a sampler filters it, against a reference."""
    from .preview import render, save, table

    # each filter's time is the faster of two frames: the first loads the compiled kernels
    result = render(texture, scene=scene, filter=filter_name, size=size, reference=reference,
                    alpha_cutoff=alpha_cutoff, wrap=wrap, runs=2)
    if output:
        save(result, output)
    summary = result.to_dict()
    summary["output"] = output
    if as_json:
        _print_json(summary)
        return
    click.echo(table(result))
    if output:
        click.echo(output)


@cli.command()
@click.argument("path", type=click.Path())
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True, help="Port on 127.0.0.1 (0: a free one).")
@click.option("--open", "open_browser", is_flag=True, help="Open the page in the default browser.")
@click.option("--source", type=click.Path(dir_okay=False), default=None,
              help="A texture's source image, for the difference view [default: from a scene.json beside it].")
@click.option("--screenshot", "shot", type=click.Path(dir_okay=False), default=None,
              help="Render the page in headless Chromium to this PNG and exit.")
@click.option("--size", default="1280x720", show_default=True, help="Screenshot size WxH.")
@_guarded
def view(path, port, open_browser, source, shot, size):
    """Show a `texcook scene` output folder, a glTF model or a texture in three.js in a browser."""
    from . import view as viewer

    viewer.require_three()
    if shot:
        textures = viewer.screenshot(path, shot, viewer.parse_size(size), source=source)
        refused = [t for t in textures if not t.get("ok")]
        click.echo(f"{shot}: {len(textures) - len(refused)} texture(s) shown as KTX2"
                   + (f", {len(refused)} refused by this browser" if refused else ""))
        for t in refused:
            click.echo(f"texcook: note: {printable(t.get('name'))}: {t.get('why')}", err=True)
        return
    site = viewer.open_site(path, source)
    server = viewer.Server(site, viewer.THREE_DIR, port)
    click.echo(f"texcook view: {server.url} (Ctrl-C stops)")
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.serve_forever()
    finally:
        server.close()


def _parse_dask(ctx, param, value):
    """local or local:N -> N (0: one per core)."""
    if value is None:
        return None
    name, _, count = value.partition(":")
    if name != "local" or (count and not (count.isdigit() and int(count) >= 1)):
        raise click.BadParameter("expected local or local:N (N workers)")
    return int(count) if count else 0


class _ProgressBar:
    """files done, failures, rate and time left on stderr (a terminal only),
    advanced as each file finishes."""

    def __init__(self):
        self.bar = None
        self.failed = 0

    def __call__(self, entry, count):
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=count, unit="file", file=sys.stderr, dynamic_ncols=True, leave=False,
                            mininterval=0)
        if entry["status"] == "failed" or entry.get("passed") is False:
            self.failed += 1
            self.bar.set_postfix(failed=self.failed, refresh=False)
        self.bar.update(1)

    def write(self, text):
        """A line on stderr that the bar does not overwrite."""
        if self.bar is not None:
            self.bar.clear()
        click.echo(text, err=True)
        if self.bar is not None:
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _batch_notes(report):
    """The files' notes collapsed: one line per distinct note, with how many
    files it concerns (or the file, when one)."""
    for row in report.get("notes", ()):
        who = f"{row['files']} files" if row["files"] > 1 else row["input"]
        yield f"texcook: note: {who}: {row['note']}"


@cli.command()
@click.argument("inputs", nargs=-1, type=click.Path())
@click.option("-o", "--outdir", required=True, type=click.Path(file_okay=False),
              help="Output folder: outputs mirror the input folders; the state file lives here.")
@click.option("--manifest", type=click.Path(dir_okay=False), default=None,
              help="TOML rules: glob pattern -> recipe, first match wins (see docs/batch.md).")
@click.option("--recipe", "recipe_path", type=click.Path(dir_okay=False), default=None,
              help="Bake every file with this recipe (.json or .toml); --format, --preset and --rdo given here "
                   "override it.")
@recipe_options("format", "preset", "rdo")
@click.option("--container", default=None,
              help="Output container (ktx2, dds, astc) where a rule does not set one [default: ktx2].")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes [default: all cores; fewer when the memory budget holds fewer].")
@click.option("--force", is_flag=True, help="Bake everything, up to date or not.")
@click.option("--dry-run", is_flag=True, help="Print what would be baked and why; bake nothing.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), default=None,
              help="Write a JSON report of every file.")
@click.option("--min-psnr", type=float, default=None,
              help="Measure PSNR per level; a file below this (dB) fails the batch.")
@click.option("--scheduler", default=None, help="Run on a dask.distributed scheduler, e.g. tcp://host:8786.")
@click.option("--dask", "dask_local", default=None, callback=_parse_dask,
              help="Run on a local Dask cluster: local or local:N workers.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no notes; failures and the summary only.")
@_guarded
def batch(inputs, outdir, manifest, recipe_path, **options):
    """Bake many INPUTS (files, folders, globs) into OUTDIR, skipping what is up to date."""
    from . import batch as batchlib

    try:
        with batchlib.sigterm_as_interrupt():
            _batch(batchlib, inputs, outdir, manifest, recipe_path, options)
    except batchlib.Terminated:  # outside the bakes (planning, printing): nothing to record
        click.echo("texcook: terminated (SIGTERM)", err=True)
        sys.exit(143)


def _batch(batchlib, inputs, outdir, manifest, recipe_path, options):
    """`options`: the command's other options by name (the recipe settings --format and --preset among them)."""
    import signal

    from ._jit import set_first_use_notice
    from .errors import OutputError
    from .fileio import atomic_write

    fmt, preset, rdo, container, jobs, force, dry_run, report_path, min_psnr, scheduler, dask_local, quiet = (
        options[k] for k in ("format", "preset", "rdo", "container", "jobs", "force", "dry_run", "report_path",
                             "min_psnr", "scheduler", "dask_local", "quiet"))
    if scheduler is not None and dask_local is not None:
        raise UsageError("give --scheduler or --dask, not both")
    if report_path is not None and not os.path.isdir(os.path.dirname(os.path.abspath(report_path))):
        raise OutputError("the report's folder does not exist", report_path)  # known before any bake
    if manifest is not None:
        if recipe_path or fmt or preset or rdo is not None:
            raise UsageError("with --manifest the rules give the recipes: drop --recipe, --format, --preset and --rdo")
        rules = batchlib.load_manifest(manifest)
        jobs_list = batchlib.plan(inputs or rules.inputs, outdir, rules=rules, container=container)
    else:
        if not inputs:
            raise UsageError("name the inputs (files, folders, globs) or give --manifest")
        recipe = _recipe_from({"format": fmt, "preset": preset, "rdo": rdo},
                              None if recipe_path is None else _load_recipe(recipe_path))
        jobs_list = batchlib.plan(inputs, outdir, recipe=recipe, container=container)
    if not quiet:
        for note in jobs_list.notes:
            click.echo(f"texcook: note: {printable(manifest)}: {printable(note)}", err=True)
    backend = "processes" if scheduler is None and dask_local is None else "dask"
    workers = dask_local or jobs
    bar = _ProgressBar() if sys.stderr.isatty() and not dry_run and not quiet else None
    set_first_use_notice("off" if quiet else "line")  # the workers inherit it; the bar is the live line

    def note(text):  # a batch-wide note as it arises, above the bar when there is one
        line = f"texcook: note: {printable(text)}"
        if bar is not None:
            bar.write(line)
        else:
            click.echo(line, err=True)

    try:
        report = batchlib.run(jobs_list, outdir, workers=workers, backend=backend, scheduler=scheduler,
                              force=force, dry_run=dry_run, min_psnr=min_psnr, progress=bar,
                              notify=None if quiet else note)
        stopped = None
    except batchlib.Interrupted as stop:
        report, stopped = stop.report, stop.signum
    finally:
        if bar is not None:
            bar.close()
    if dry_run:
        for entry in report["files"]:
            click.echo(batchlib.dry_run_line(entry))
    for entry in report["files"]:
        if entry["status"] == "failed":
            click.echo(f"texcook: failed: {printable(entry['reason'])}", err=True)
        elif entry.get("passed") is False:
            click.echo(f"texcook: below --min-psnr: {entry['output']}: {_db(entry['psnr'])} dB", err=True)
    if not quiet:
        for line in _batch_notes(report):
            click.echo(printable(line), err=True)
    if report_path is not None:
        atomic_write(report_path, (json.dumps(_json_value(report), indent=2) + "\n").encode())
    click.echo(batchlib.summary_line(report))
    if stopped is not None:
        how = "terminated (SIGTERM)" if stopped == signal.SIGTERM else "interrupted"
        click.echo(f"texcook: {how}; what finished is recorded, run again to resume", err=True)
        sys.exit(128 + stopped)
    if not report["ok"]:
        sys.exit(1)


def main():
    try:
        cli(prog_name="texcook")
    except SystemExit as exc:
        if exc.code == 130:
            # interrupted: every output is already cleaned up, so skip the interpreter's
            # teardown (numba, OpenImageIO), which takes most of a second
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(130)
        raise


if __name__ == "__main__":
    main()
