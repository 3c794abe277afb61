def tag(text):
    return " ".join(w + "/X" for w in text.replace(".", "").replace(",", "").split())
