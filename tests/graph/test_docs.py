"""The documentation cannot rot: every code block of the tutorials runs, and the generated
reference tables hold what the code holds, every dotted module name written in the tree names
a module (scripts/doc_names.py), and a dead link or anchor fails the site's build however
it is started (scripts/build_docs.sh, which scripts/test.sh runs, and a plain
``mkdocs build --strict``).

Tutorial blocks (and README.md's) run in order, one page per test, in an empty scratch
directory that has only the repository's inputs the page names (``config/``, the shipped bags
``bags/commute_*`` when the page uses them, links), with the project's ``.venv/bin`` first on
``PATH``: the commands work as a user types them from a fresh clone, and every folder a
command writes into is one it creates itself.
A block titled with a file name (```` ```yaml title="my.yaml" ````) is written to that file
(a params file among them is checked by ``load_run_config``); a block preceded by
``<!-- not run: REASON -->`` is skipped.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import pytest
import yaml
from support.example_plugin import install_example_plugin
from support.paths import REPO

from trust_av.cli import reference
from trust_av.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_av_common.params import read_params_file
from trust_av_common.topics import TOPICS, topic_table_markdown

DOCS = REPO / 'docs'
TUTORIALS = sorted((DOCS / 'tutorials').glob('*.md')) + sorted((DOCS / 'how-to').glob('*.md'))
WALL_CLOCK_PAGES = {'connect-a-vehicle.md'}      # trust-av shadow runs at real time
PLUGIN_PAGES = {'write-a-plugin.md'}     # run with the example plug-in installed
INCLUDE = '--8<-- '                      # a block that includes a repository file
RUN = ('bash', 'python')
FENCE = re.compile(r'^(?P<skip><!-- not run: (?P<reason>[^>]+) -->\n)?```(?P<lang>[a-z]*)'
                   r'(?P<attrs>[^\n]*)\n(?P<body>.*?)^```\s*$', re.MULTILINE | re.DOTALL)
TITLE = re.compile(r'title="([^"]+)"')


@dataclass(frozen=True)
class Block:
    """One fenced code block of a page."""

    lang: str
    body: str
    line: int
    title: str = ''
    skip_reason: str = ''


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of ``page``, in order."""
    text = page.read_text(encoding='utf-8')
    found = []
    for match in FENCE.finditer(text):
        title = TITLE.search(match['attrs'])
        found.append(Block(match['lang'], match['body'], text.count('\n', 0, match.start()) + 1,
                           title.group(1) if title else '', match['reason'] or ''))
    return found


SHIPPED_BAGS = ('commute_am', 'commute_pm')   # tracked under bags/ (.gitignore)
README_INPUTS = ('scripts', 'src', 'vendor', 'requirements.txt')   # what run_main.sh reads


def scratch(tmp_path: Path, page_text: str = '') -> Path:
    """An empty working directory with only the repository's inputs that ``page_text``
    names: ``config/`` always, a shipped bag when the page names ``bags/<it>``. Nothing a
    command writes exists yet (no ``bags/``, no ``results/``)."""
    work = tmp_path / 'work'
    work.mkdir(parents=True)
    (work / 'config').symlink_to(REPO / 'config')
    for name in SHIPPED_BAGS:
        if f'bags/{name}' in page_text:
            (work / 'bags').mkdir(exist_ok=True)
            (work / 'bags' / name).symlink_to(REPO / 'bags' / name)
    return work


def run_block(block: Block, page: Path, work: Path, base_env: dict[str, str]) -> None:
    env = {**base_env, 'PATH': f'{Path(sys.executable).parent}{os.pathsep}'
                                 f'{os.environ.get("PATH", "")}'}
    if block.lang == 'bash':
        command = ['bash', '-euo', 'pipefail', '-c', block.body]
    else:    # as a saved script, as a reader runs it (python -c would hide a missing
        script = work / f'block_{block.line}.py'  # __main__ guard for worker processes)
        script.write_text(block.body, encoding='utf-8')
        command = [sys.executable, str(script)]
    proc = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True,
                          timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, (f'{page.name}:{block.line}: exit {proc.returncode}\n'
                                  f'{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}')


@pytest.mark.parametrize('page', [
    pytest.param(p, id=p.stem,
                 marks=[pytest.mark.wall_clock] if p.name in WALL_CLOCK_PAGES else [])
    for p in TUTORIALS])
def test_tutorial_blocks_run(page: Path, tmp_path: Path) -> None:
    work = scratch(tmp_path, page.read_text(encoding='utf-8'))
    env = (install_example_plugin(tmp_path / 'plugin') if page.name in PLUGIN_PAGES
           else dict(os.environ))
    assert run_page(page, work, env), f'{page.name} has no runnable block'


def test_readme_blocks_run(tmp_path: Path) -> None:
    """README.md's commands, from a folder laid out as a fresh clone (its scripts and
    sources, this environment as its .venv): the main job writes ``bags/`` itself."""
    work = scratch(tmp_path, (REPO / 'README.md').read_text(encoding='utf-8'))
    for name in README_INPUTS:
        (work / name).symlink_to(REPO / name)
    env = {**os.environ, 'TRUST_AV_VENV': str(Path(sys.executable).parents[1])}
    # the environment up to date from the repository itself first: were its stamp stale, the
    # README's set-up would re-install the packages editable from this scratch folder
    setup = subprocess.run(['bash', str(REPO / 'scripts' / 'bootstrap.sh')], env=env,
                           capture_output=True, text=True, timeout=1800, check=False)
    assert setup.returncode == 0, setup.stderr[-3000:]
    assert run_page(REPO / 'README.md', work, env) >= 1
    assert (work / 'bags' / 'main_us06' / 'metadata.yaml').is_file()
    assert (work / 'bags' / 'main_us06.png').is_file()


def run_page(page: Path, work: Path, env: dict[str, str]) -> int:
    """Run the blocks of ``page`` in order in ``work``; the number of blocks run."""
    ran = 0
    for block in blocks(page):
        if block.skip_reason:
            continue
        if block.body.startswith(INCLUDE):
            # the page shows a repository file; the blocks after it run that file
            included = REPO / block.body[len(INCLUDE):].strip().strip('"')
            assert included.is_file(), f'{page.name}:{block.line}: no file {included}'
            continue
        if block.title:
            target = work / block.title
            target.write_text(block.body, encoding='utf-8')
            if block.lang == 'yaml' and 'ros__parameters' in block.body:
                load_run_config(target)           # a params file a tutorial gives is valid
        elif block.lang in RUN:
            run_block(block, page, work, env)
            ran += 1
    return ran


def test_block_parsing_sees_titles_and_skips(tmp_path: Path) -> None:
    """The runner's reading of a page: a title, a skip marker, plain blocks; in order."""
    page = tmp_path / 'page.md'
    page.write_text('text\n```bash\necho a\n```\n\n<!-- not run: needs a car -->\n```bash\n'
                    'ros2 run x y\n```\n```yaml title="p.yaml"\nk: 1\n```\n```text\nout\n```\n')
    found = blocks(page)
    assert [(b.lang, b.title, b.skip_reason) for b in found] == [
        ('bash', '', ''), ('bash', '', 'needs a car'), ('yaml', 'p.yaml', ''), ('text', '', '')]
    assert found[0].body == 'echo a\n' and found[0].line == 2


def test_a_failing_block_fails_the_test(tmp_path: Path) -> None:
    page = tmp_path / 'page.md'
    with pytest.raises(AssertionError, match=r'page\.md:3: exit 3'):
        run_block(Block('bash', 'exit 3\n', 3), page, tmp_path, dict(os.environ))


def test_every_tutorial_is_in_the_nav_the_readme_and_on_the_home_page() -> None:
    """Every page of docs/tutorials/ (the folder decides, not a list here)."""
    nav = (REPO / 'mkdocs.yml').read_text()
    readme = (REPO / 'README.md').read_text()
    home = (DOCS / 'index.md').read_text()
    names = sorted(page.stem for page in (DOCS / 'tutorials').glob('*.md'))
    assert len(names) >= 6
    missing = [name for name in names if f'tutorials/{name}.md' not in nav
               or f'docs/tutorials/{name}.md' not in readme
               or f'](tutorials/{name}.md)' not in home]
    assert not missing, f'tutorials missing from the nav, the README or docs/index.md: {missing}'


def test_python_example_is_the_documented_entry_points() -> None:
    """The tutorial's Python example calls load_run_config -> load_trace -> simulate."""
    python = [b.body for b in blocks(DOCS / 'tutorials' / 'own-trace-or-bag.md')
              if b.lang == 'python']
    example = next(body for body in python if 'simulate(' in body)
    order = [example.index(f'{name}(') for name in ('load_run_config', 'load_trace',
                                                    'simulate')]
    assert order == sorted(order)


def test_readme_is_short_and_keeps_the_two_commands() -> None:
    readme = (REPO / 'README.md').read_text()
    assert len(readme.encode()) < 10_000
    assert 'bash scripts/run_main.sh' in readme and 'bash scripts/test.sh' in readme
    assert 'δ·t = 60' in readme
    links = re.findall(r'\]\(([^)#]+)(?:#[^)]*)?\)', readme)
    assert len(links) > 15
    missing = [link for link in links if not (REPO / link).is_file()]
    assert not missing, f'README links to missing files: {missing}'


def test_docs_reference_nothing_outside_the_repository() -> None:
    models = REPO / 'src' / 'human_driver_sim' / 'human_driver_sim' / 'models'
    shipped = [*models.glob('*.yaml'), *models.glob('*.json')]   # their provenance fields
    assert shipped
    pages = [*DOCS.rglob('*.md'), REPO / 'README.md', REPO / 'config' / 'trust_av.yaml',
             *shipped]
    for page in pages:
        text = page.read_text(encoding='utf-8')
        for outside in ('/work/shared', '../shared', 'shared/docs', 'DESIGN section',
                        'DESIGN.md'):
            assert outside not in text, f'{page.relative_to(REPO)} names {outside!r}'


def test_code_cites_the_site_not_a_missing_design_file() -> None:
    for root in ('src', 'tests', 'scripts', 'benchmarks', 'config'):
        for path in (REPO / root).rglob('*'):
            if path.suffix in ('.py', '.yaml', '.sh') and path != Path(__file__):
                text = path.read_text(encoding='utf-8')
                assert 'DESIGN' not in text, f'{path.relative_to(REPO)} cites DESIGN'


def test_cited_concept_pages_exist() -> None:
    """Every docs/... page the code, config and tests cite is in the repository."""
    cited = re.compile(r'docs/([\w/.-]+\.md)')
    for root in ('src', 'tests', 'config', 'scripts', 'benchmarks'):
        for path in (REPO / root).rglob('*'):
            if path.suffix in ('.py', '.yaml', '.sh'):
                for name in cited.findall(path.read_text(encoding='utf-8')):
                    assert (DOCS / name).is_file(), f'{path.relative_to(REPO)} cites docs/{name}'


def test_generated_topic_table_is_the_code_table() -> None:
    page = reference.fill((DOCS / 'reference' / 'topics-and-qos.md').read_text())
    assert topic_table_markdown() in page and '<!-- generated' not in page
    assert all(f'| `{t.name}` | `{t.msgtype}` |' in page for t in TOPICS)


def test_generated_parameter_table_has_every_shipped_parameter() -> None:
    page = reference.fill((DOCS / 'reference' / 'parameters.md').read_text())
    for section, values in read_params_file(DEFAULT_PARAMS_FILE).items():
        for name in values:
            assert f'| `{name}` |' in page, f'{section}: {name} missing'
    row = next(line for line in page.splitlines() if line.startswith('| `dt_s` |'))
    assert '| s | [0.01, 10] |' in row             # CONTROL_STEP_RANGE_S, with its unit
    row = next(line for line in page.splitlines() if line.startswith('| `alpha` |'))
    assert '| [0, 1] |' in row and '(changeable at run time in wall mode)' in row


def test_generated_cli_reference_has_every_command_and_option() -> None:
    page = reference.fill((DOCS / 'reference' / 'cli.md').read_text())
    for command in ('simulate', 'run', 'shadow', 'reproduce', 'trace-to-bag', 'repair-bag',
                    'train-gru', 'fit-driver', 'eval-driver'):
        assert f'### `trust-av {command}`' in page
    assert '## `trust-monitor-estimate`' in page and '`-o OUTPUT`, `--output OUTPUT`' in page
    assert '`--max-steps MAX_STEPS`' in page and str(REPO) not in page
    assert 'default `config/trust_av.yaml`' in page    # paths shown relative to the repository


def test_an_unknown_marker_is_refused() -> None:
    with pytest.raises(reference.UnknownTableError, match="no generated table 'tables'"):
        reference.fill('# x\n<!-- generated: tables -->\n')


def test_generated_vehicle_interface_is_the_planners_view_of_the_code_table() -> None:
    """Inputs: what the planner subscribes from outside the vehicle side; outputs: what the
    planner and the monitor publish, each with its wall-mode QoS and frame."""
    page = reference.fill((DOCS / 'tutorials' / 'connect-a-vehicle.md').read_text())
    rows = {line.split(' | ')[1]: line for line in page.splitlines()
            if line.startswith(('| in |', '| out ('))}
    assert set(rows) == {'`/preceding_vehicle/odom`', '`/preceding_vehicle/speed_preview`',
                         '`/ego/odom`', '`/human/odom`', '`/ego/plan`', '`/ego/expected_plan`',
                         '`/ego/accel_cmd`', '`/ego/planner_status`', '`/trust_monitor/trust`',
                         '`/vehicle_markers`'}
    command = rows['`/ego/accel_cmd`']
    assert command.startswith('| out (planner) |') and "the AV's body frame" in command
    assert 'deadline 2 control periods' in command
    assert 'no deadline unless input_deadline_qos' in rows['`/ego/odom`']


def test_pins_named_in_the_docs_are_the_requirements() -> None:
    """A `pip install name==version` in a page is the version requirements.txt pins."""
    pinned = {line.split('==')[0].lower(): line.split('==')[1].strip()
              for line in (REPO / 'requirements.txt').read_text().splitlines()
              if '==' in line and not line.startswith('#')}
    named = [(page, name, version) for page in [*DOCS.rglob('*.md'), REPO / 'README.md']
             for command in re.findall(r'pip install ([^`\n]+)', page.read_text())
             for name, version in re.findall(r'([A-Za-z0-9_.-]+)==([0-9][\w.]*)', command)]
    assert len(named) >= 5
    for page, name, version in named:
        assert pinned.get(name.lower()) == version, f'{page.name}: {name}=={version}'


def test_the_site_needs_no_internet() -> None:
    """No web fonts (Material loads Google Fonts unless theme.font is false), no external
    JavaScript or CSS, and strict mode on."""
    config = yaml.safe_load((REPO / 'mkdocs.yml').read_text())
    assert config['theme']['font'] is False and config['strict'] is True
    for key in ('extra_javascript', 'extra_css'):
        assert not any('://' in str(entry) for entry in config.get(key, []))
    assert config['hooks'] == ['docs/hooks.py']


def test_every_generated_table_says_where_to_find_it() -> None:
    """In the Markdown source (on GitHub) a marker is a bare comment: the line after it says
    where the table is; the site replaces both with the table."""
    marker = re.compile(r'^<!-- generated: [a-z_]+ -->\n(.*)$', re.MULTILINE)
    pages = [p for p in DOCS.rglob('*.md') if marker.search(p.read_text())]
    assert len(pages) >= 4
    for page in pages:
        text = page.read_text()
        assert all(line.startswith('> Generated table: ') for line in marker.findall(text)), \
            page.name
        filled = reference.fill(text)
        assert '<!-- generated' not in filled and '> Generated table:' not in filled


def doc_names() -> ModuleType:
    """scripts/doc_names.py, imported from its file."""
    name = 'scripts_doc_names'
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, REPO / 'scripts' / 'doc_names.py')
        assert spec is not None and spec.loader is not None
        sys.modules[name] = importlib.util.module_from_spec(spec)   # for its dataclass
        spec.loader.exec_module(sys.modules[name])
    module = sys.modules[name]
    return module


def test_every_dotted_module_name_in_the_tree_names_a_module() -> None:
    names = doc_names()
    found = names.check()
    assert not found, 'names of no module (rename them, or mark a planted one with ' \
        '"doc-names: off"):\n' + '\n'.join(map(str, found))


def test_a_stale_module_name_is_found(tmp_path: Path) -> None:
    """Planted in a page and in a docstring: a module that does not exist, an object its
    module lacks, an old path of a MOVED table, a module's short name gone from the tree,
    a current short name with a missing object; a parameter, an entry-point group, a file
    name and a marked line pass."""
    names = doc_names()
    page = tmp_path / 'page.md'
    # doc-names: off (the stale names planted here are the test's input)
    page.write_text('See `trust_monitor.ros_support.QOS` and `trust_av_common.kinematics.nope`.\n'
                    'Old: `trust_monitor.trust_interface`; gone: `trust_interface.numeric_bound`;'
                    ' `paper_trust.NoSuchThing`.\n'
                    'Fine: `trust_av_common.kinematics.hold_gap_plan`,'
                    ' `paper_trust.TrustEstimator`, `preceding_traffic.trace`,'
                    ' `trust_av.predictors`, `config/trust_av.yaml`.\n'
                    '<!-- doc-names: off -->\n`trust_av.made_up`\n<!-- doc-names: on -->\n')
    module = tmp_path / 'module.py'
    module.write_text('"""Uses :func:`trust_monitor.graph_interface.topics`."""\n')
    found = {(Path(item.path).name, item.line, item.name)
             for item in names.check(scanned=[page, module])}
    assert found == {('page.md', 1, 'trust_monitor.ros_support.QOS'),
                     ('page.md', 1, 'trust_av_common.kinematics.nope'),
                     ('page.md', 2, 'trust_monitor.trust_interface'),
                     ('page.md', 2, 'trust_interface.numeric_bound'),
                     ('page.md', 2, 'paper_trust.NoSuchThing'),
                     ('module.py', 1, 'trust_monitor.graph_interface.topics')}
    # doc-names: on


def planted_site(root: Path, anchor: str) -> Path:
    """A two-page site with the project's validation rules, its index linking
    ``other.md#anchor``; returns its mkdocs.yml."""
    validation = yaml.safe_load((REPO / 'mkdocs.yml').read_text())['validation']
    (root / 'docs').mkdir()
    (root / 'docs' / 'index.md').write_text(f'# Home\n\n[there](other.md#{anchor})\n')
    (root / 'docs' / 'other.md').write_text('# Other\n\n## A heading {#stable}\n')
    config = root / 'mkdocs.yml'
    config.write_text(yaml.safe_dump({
        'site_name': 'planted', 'docs_dir': 'docs', 'strict': True,
        'markdown_extensions': ['attr_list', 'toc'], 'validation': validation}))
    return config


@pytest.mark.parametrize('anchor', ['stable', 'gone'])
def test_a_dead_anchor_fails_the_build_however_it_is_started(anchor: str,
                                                             tmp_path: Path) -> None:
    """The test command's build (scripts/build_docs.sh) and a plain ``mkdocs build --strict``
    agree: both pass with the explicit ``{#stable}`` anchor, both fail on a dead one."""
    config = planted_site(tmp_path, anchor)
    env = dict(os.environ, PATH=f'{Path(sys.executable).parent}:{os.environ["PATH"]}')
    ours = subprocess.run(['bash', str(REPO / 'scripts' / 'build_docs.sh'), '-f', str(config),
                           '--site-dir', str(tmp_path / 'a')], capture_output=True, text=True,
                          env=env, check=False)
    plain = subprocess.run([sys.executable, '-m', 'mkdocs', 'build', '--strict', '-f',
                            str(config), '--site-dir', str(tmp_path / 'b')],
                           capture_output=True, text=True, env=env, check=False)
    dead = anchor == 'gone'
    assert (ours.returncode != 0, plain.returncode != 0) == (dead, dead), (ours, plain)
    assert ("does not contain an anchor '#gone'" in ours.stdout) == dead, ours.stdout
    assert 'INFO' not in ours.stdout


def test_the_test_command_builds_the_site_with_the_shared_script() -> None:
    test_sh = (REPO / 'scripts' / 'test.sh').read_text()
    assert 'bash scripts/build_docs.sh' in test_sh
    commands = [line for line in test_sh.splitlines()
                if not line.lstrip().startswith(('#', 'echo'))]
    assert not [line for line in commands if 'mkdocs build' in line]


def test_a_heading_that_names_a_module_has_a_stable_anchor() -> None:
    """A heading that carries a dotted module name is linked through an explicit ``{#id}``:
    a module's rename changes the heading's text, never its anchor."""
    names = '|'.join(doc_names().packages())
    module = re.compile(rf'`(?:{names})\.[\w.]+`')
    missing = [f'{page.relative_to(REPO)}:{number}' for page in DOCS.rglob('*.md')
               if page.name != 'CHANGELOG.md'
               for number, line in enumerate(page.read_text().splitlines(), start=1)
               if line.startswith('#') and module.search(line)
               and not re.search(r'\{#[\w-]+\}\s*$', line)]
    assert not missing, f'headings naming a module without an explicit {{#id}}: {missing}'
