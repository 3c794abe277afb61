"""The README opens with the two set-up commands, and .ci/run runs the README's test command."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bash_blocks(text: str) -> list[str]:
    blocks, inside, current = [], False, []
    for line in text.splitlines():
        if line.strip() == "```bash":
            inside, current = True, []
        elif line.strip() == "```" and inside:
            blocks.append("\n".join(current).strip())
            inside = False
        elif inside:
            current.append(line)
    return blocks


def test_readme_opens_with_two_commands_and_ci_runs_the_test_one():
    readme = (ROOT / "README.md").read_text()
    blocks = _bash_blocks(readme)
    assert len(blocks) >= 2
    first_prose = readme.split("```bash")[0]
    assert first_prose.count("\n\n") <= 4  # the commands come right after the introduction
    main_cmd, test_cmd = blocks[0], blocks[1]
    assert "pip install -q torch==2.13.0" in main_cmd and "controlmm " in main_cmd
    assert "pytest" in test_cmd and '".[test]"' in test_cmd
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci
